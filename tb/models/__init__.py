"""Pure-Python golden and peer models, written from the spec, never from the RTL."""
