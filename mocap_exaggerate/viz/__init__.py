"""Pictures: still and animated previews (`preview`) and the batch's HTML report (`report`)."""
