"""The command-line application (click), kept apart from the library."""
