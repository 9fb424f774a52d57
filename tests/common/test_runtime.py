"""The service runtime: announce, health, clean shutdown on SIGTERM within 2 s."""

import signal
import subprocess
import sys
import time

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.testing import wait_until
from asibot.timing import Ticker

SERVICE = """
import sys
from asibot import runtime
NAME = "demo"
class Svc(runtime.Service):
    def health(self): return {"answer": 42}
    def close(self): print("closed", flush=True)
def add_arguments(parser): pass
def build(bus, args):
    bus.serve(f"rb/{args.robot}/cart/rpc/stat", lambda req: {"robot": args.robot})
    return Svc()
raise SystemExit(runtime.run(sys.modules[__name__]))
"""


def test_service_announces_serves_reports_health_and_stops_cleanly(router):
    proc = subprocess.Popen([sys.executable, "-c", SERVICE, "--robot", "r9", "--log-format", "json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with Bus("t") as bus:
        health = []
        bus.subscribe(keys.health("demo", "r9"), m.Health, health.append)
        wait_until(lambda: keys.service("demo", "r9") in bus.alive(), 10)
        assert bus.call(keys.cart_rpc("r9", "stat"))["robot"] == "r9"
        wait_until(lambda: health, 5)
        assert health[0].details == {"answer": 42} and health[0].pid == proc.pid
        t = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(3) == 0
        assert time.monotonic() - t < 2.0
        out, err = proc.communicate()
        assert "closed" in out
        assert '"service": "demo"' in err  # structured (JSON) log lines
        wait_until(lambda: keys.service("demo", "r9") not in bus.alive(), 2)


def test_a_service_that_cannot_start_says_why_and_exits_1(router):
    code = ("import sys\nfrom asibot import runtime\nNAME = 'demo'\ndef add_arguments(p): pass\n"
            "def build(bus, args): raise ValueError('no robot called moon')\n"
            "raise SystemExit(runtime.run(sys.modules[__name__]))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=20)
    assert r.returncode == 1 and "no robot called moon" in r.stderr


def test_ticker_skips_missed_ticks_instead_of_bunching_and_stops():
    t = Ticker(100.0)
    t.wait()
    time.sleep(0.055)  # miss about five deadlines
    t.wait()
    assert t.overruns == 1
    t.wait()  # the schedule moved on: this is a normal, single tick
    assert t.stats()["n"] == 2
    t.stop()
    assert t.wait() is False
    assert list(t) == []
