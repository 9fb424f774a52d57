"""What the page's guard (asibot.web.guard) costs on the jog path, before and after in one run.

One web service on the in-memory bus with an ideal ASIBOT driver and the real kinematics
server, served by uvicorn twice on loopback: as shipped (guarded) and with the guard taken off
(the reference, today's server before the guard). A jog step is POSTed alternately to each,
as the page sends it, and timed from the press to the first arm command the driver hears and
to the page's answer. The hold-to-move buttons stream over the WebSocket, checked once when
it opens, so their beats pay nothing; the handshake is timed too.

    python bench/bench_guard.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import uvicorn

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from table import QUICK_HELP, print_table  # noqa: E402

from asibot import keys, robots  # noqa: E402
from asibot.bus import Bus  # noqa: E402
from asibot.kinematics.model import solver_for  # noqa: E402
from asibot.kinematics.server import KinematicsServer  # noqa: E402
from asibot.messages import ArmCommand  # noqa: E402
from asibot.testing import IdealDriver, free_port, memory_bus, wait_until  # noqa: E402
from asibot.web import guard, service  # noqa: E402

ROBOT = "asibot-sim"


def serve(app) -> tuple[uvicorn.Server, str]:
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    threading.Thread(target=server.run, daemon=True).start()
    wait_until(lambda: server.started, timeout=10)
    return server, f"http://127.0.0.1:{port}"


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = parser.parse_args()
    presses = 2 if args.quick else 200
    with memory_bus("bench-guard"), tempfile.TemporaryDirectory() as data:
        spec = robots.get(ROBOT)
        driver = IdealDriver(ROBOT, spec)
        kinematics = KinematicsServer(Bus("kinematics"), ROBOT, solver_for(spec), spec)
        web = service.build(Bus("web"), argparse.Namespace(host="127.0.0.1", port=8080, lan=False,
                                                             new_token=False, data=Path(data)))
        wait_until(lambda: ROBOT in web.fleet.ids(), timeout=10)
        heard: list[float] = []
        listener = Bus("bench")
        listener.subscribe(keys.arm_command(ROBOT), ArmCommand, lambda c: heard.append(time.perf_counter()))
        guarded, guarded_url = serve(web.app)
        bare, bare_url = serve(web.app.app)           # PageGuard's inner app: the server before it
        results: dict[str, dict[str, list[float]]] = {"guarded": {"command": [], "answer": [], "ws": []},
                                                       "bare": {"command": [], "answer": [], "ws": []}}
        headers = {guard.HEADER: web.web.session, "Origin": guarded_url}
        try:
            with httpx.Client(timeout=10) as client:
                for i in range(presses * 2):
                    name, url = ("guarded", guarded_url) if i % 2 == 0 else ("bare", bare_url)
                    step = {"space": "joint", "axis": 0, "direction": 1 if (i // 2) % 2 == 0 else -1,
                            "level": 5, "step": 0.5}
                    before = len(heard)
                    start = time.perf_counter()
                    reply = client.post(f"{url}/api/robots/{ROBOT}/step", json=step,
                                        headers={**headers, "Origin": url})
                    answered = time.perf_counter()
                    assert reply.status_code == 200, reply.text
                    wait_until(lambda: len(heard) > before, timeout=5, interval=0.0005)
                    results[name]["command"].append(heard[before] - start)
                    results[name]["answer"].append(answered - start)
                    kinematics.ctl.stop()
                    wait_until(lambda: kinematics.ctl.state == "not_controlling", timeout=5, interval=0.001)
                    if i % 10 == 0:                         # one handshake each, in turn first
                        pair = [("guarded", guarded_url), ("bare", bare_url)][::1 if i % 20 == 0 else -1]
                        for ws_name, ws_url in pair:
                            results[ws_name]["ws"].append(_handshake(ws_url, web.web.session))
        finally:
            guarded.should_exit = bare.should_exit = True
            web.close()
            kinematics.close()
            driver.close()
    rows = []
    for what, key in (("jog step press to first arm command", "command"), ("jog step press to answer", "answer"),
                      ("WebSocket open to hello", "ws")):
        for q in (50, 99):
            rows.append((f"{what}, p{q}", pct(results["guarded"][key], q), pct(results["bare"][key], q), "ms"))
    print_table(rows, header=("what", "with the guard", "without (reference)", "unit"))


def _handshake(url: str, session: str) -> float:
    from websockets.sync.client import connect
    start = time.perf_counter()
    with connect(url.replace("http", "ws") + f"/ws?session={session}", origin=url) as ws:
        ws.recv(timeout=5)
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
