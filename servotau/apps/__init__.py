"""Applications on top of the library: the command-line commands, the demo and their helpers."""
