"""A second process for multi-process bus tests: `python peer.py ROLE KEY`.

Roles: `echo` serves RPC on KEY (and refuses {"refuse": true}, sleeps {"sleep": s});
`publish` publishes ArmState on KEY every 10 ms forever; `listen` subscribes to ArmState on
KEY and serves KEY/count with what it received; `token` declares a liveliness token KEY.
Every role prints READY once set up.
"""

import sys
import threading
import time

from asibot import messages as m
from asibot.bus import Bus
from asibot.errors import RpcError


def main(role: str, key: str) -> None:
    bus = Bus(f"peer-{role}")
    if role == "echo":
        def handle(req: dict) -> dict:
            if req.get("refuse"):
                raise RpcError("joint_limit", "Joint 2 would pass its limit of 135 degrees.")
            if req.get("crash"):
                raise ZeroDivisionError("boom")
            time.sleep(float(req.get("sleep", 0)))
            return {"echo": req}
        bus.serve(key, handle)
    elif role == "publish":
        pub = bus.publisher(key, m.ArmState)

        def loop() -> None:
            i = 0
            while True:
                pub.put(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))
                i += 1
                time.sleep(0.01)
        threading.Thread(target=loop, daemon=True).start()
    elif role == "listen":
        got: list[m.ArmState] = []
        bus.subscribe(key, m.ArmState, got.append)
        bus.serve(key + "/count", lambda req: {"received": len(got), "rejected": bus.rejected,
                                               "last": got[-1].positions if got else None})
    elif role == "token":
        bus.announce(key)
    print("READY", flush=True)
    threading.Event().wait()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
