"""`python -m asibot.base_driver --robot pioneer --port socket://127.0.0.1:8101`"""

from asibot import runtime
from asibot.base_driver import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
