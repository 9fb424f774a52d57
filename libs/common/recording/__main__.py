"""`python -m asibot.recording [--dir recordings] [--exclude PATTERN]`: the recorder service."""

from asibot import runtime
from asibot.recording import recorder

if __name__ == "__main__":
    raise SystemExit(runtime.run(recorder))
