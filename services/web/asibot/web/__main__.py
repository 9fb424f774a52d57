"""`python -m asibot.web [--port 8080] [--data DIR]`: the Task Creator page."""

from asibot import runtime
from asibot.web import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
