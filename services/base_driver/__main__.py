"""`python -m asibot.base_driver --robot pioneer --port socket://127.0.0.1:8101`"""

from asibot import runtime
from asibot.base_driver.service import SERVICE, add_arguments, build

if __name__ == "__main__":
    raise SystemExit(runtime.run(SERVICE, build, add_arguments=add_arguments))
