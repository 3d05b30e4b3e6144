"""Pictures: a clip's previews (`preview`: the bodies in `posing`, what is shown in `framing`, drawn
by `stills` and `animation`) and the batch's HTML report (`report`)."""
