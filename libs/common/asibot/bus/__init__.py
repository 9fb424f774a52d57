"""The bus: typed pub/sub, RPC, latching and presence between services.

`Bus(name, endpoint)` is the interface and the factory: the endpoint chooses the backend,
as python-can's `can.Bus(interface=...)` does. `tcp/HOST:PORT` (the default, from
$ASIBOT_ROUTER) is a Zenoh router (`zenoh_backend`, the only module that imports zenoh);
`mem://NAME` is every bus of this process opened on NAME (`memory`, for unit tests).
"""

from asibot.bus.base import MEMORY_SCHEME, RPC_WORKERS, Bus, Closable, Publisher
from asibot.bus.ondemand import OnDemand
from asibot.bus.zenoh_backend import (DEFAULT_ROUTER, ROUTER_ENV, open_router, router_endpoint,
                                      run_router)

__all__ = ["Bus", "Publisher", "Closable", "OnDemand", "MEMORY_SCHEME", "RPC_WORKERS", "DEFAULT_ROUTER",
           "ROUTER_ENV", "open_router", "router_endpoint", "run_router"]
