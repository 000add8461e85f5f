import sys

from harness.cli.entry import run

sys.exit(run())
