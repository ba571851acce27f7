"""The ``sustain-drake`` command line (top layer: it only parses, calls and prints)."""
