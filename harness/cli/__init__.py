"""The ``pseudolight`` command line and the benchmark runner."""
from harness.cli.main import main

__all__ = ["main"]
