"""pseudolight harness: dataset I/O, scenes -> Mitsuba, rendering, the CLI."""
