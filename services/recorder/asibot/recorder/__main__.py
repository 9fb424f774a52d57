"""`python -m asibot.recorder [--dir recordings] [--exclude PATTERN]`: the recorder service."""

from asibot import runtime
from asibot.recorder import recorder

if __name__ == "__main__":
    raise SystemExit(runtime.run(recorder))
