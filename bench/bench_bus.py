"""Bus benchmark: our layer beside raw zenoh-python, measured in the same run.

Prints two markdown tables. The first: latency is half the round trip between two processes
through one router on loopback (no clock comparison between processes needed). At 1 MiB our layer is also measured in
alternating rounds beside two raw references running at the same time: raw zenoh copying the
payload out (to_bytes), and raw zenoh carrying the same float32 array (zenoh-python takes
bytes only, so `tobytes()` out, `to_bytes()` and `frombuffer` in). The second table, in
one process, what a large message and the recorder cost without the bus: decoding a 1 MiB
depth image beside msgpack's own path (which copies every array, as decoding did before), and
our MCAP writer beside the mcap library's.

    python bench/bench_bus.py [--quick]
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import mcap.writer
import numpy as np
import zenoh

from asibot import messages as m
from asibot.bus import Bus
from asibot.bus.zenoh_backend import client_config
from asibot.recorder.recorder import RecorderService
from asibot.recorder.writer import LeanWriter
from asibot.testing import router

from table import QUICK_HELP  # bench/table.py: run as `python bench/<name>.py`

ECHO = r"""
import os, sys, zenoh
from asibot import messages as m
from asibot.bus import Bus
from asibot.bus.zenoh_backend import client_config
mode = sys.argv[1]
if mode == "ours":
    bus = Bus("echo")
    pub = bus.publisher("bench/pong", m.RgbImage, express=True)
    bus.subscribe("bench/ping", m.RgbImage, pub.put)
    pub_depth = bus.publisher("bench/pong_depth", m.DepthImage, express=True)
    bus.subscribe("bench/ping_depth", m.DepthImage, pub_depth.put)
    bus.serve("bench/rpc", lambda req: {"n": req.get("n")})
else:
    s = zenoh.open(client_config(sys.argv[2]))
    pub = s.declare_publisher("bench/pong", express=True)
    if mode == "raw-read":  # what any Python receiver must do to see the bytes: copy them out
        pub = s.declare_publisher("bench/rawpong", express=True)
        sub = s.declare_subscriber("bench/rawping", lambda sample: pub.put(sample.payload.to_bytes()))
    elif mode == "raw-array":  # the least a zenoh program that carries an array does: zenoh takes bytes only
        import numpy as np
        pub = s.declare_publisher("bench/arraypong", express=True)
        def relay(sample):
            depth = np.frombuffer(sample.payload.to_bytes(), np.float32)
            pub.put(depth.tobytes())
        sub = s.declare_subscriber("bench/arrayping", relay)
    else:
        sub = s.declare_subscriber("bench/ping", lambda sample: pub.put(sample.payload))
    def on_query(q):
        with q:
            q.reply("bench/rpc", q.payload)
    qs = s.declare_queryable("bench/rpc", on_query)
print("READY", flush=True)
sys.stdin.read()  # until the bench ends, however it ends: its end closes this pipe
os._exit(0)  # at once: an interpreter's exit waits for a zenoh session still open, for ever
"""

FLOOD = r"""
import sys, time
from asibot import messages as m
from asibot.bus import Bus
n = int(sys.argv[1])
bus = Bus("flood")
pub = bus.publisher("bench/flood", m.Battery, block=True)
time.sleep(0.5)
print("GO", flush=True)
for i in range(n):
    pub.put(m.Battery(volts=float(i)))
print("SENT", flush=True)
time.sleep(2)
"""


def spawn(code: str, *args: str) -> subprocess.Popen:
    """A helper process; its stdin is a pipe from this one, which an echo reads to know when
    the bench is gone (a bench that failed must not leave echoes holding its output open)."""
    return subprocess.Popen([sys.executable, "-c", code, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)


def pct(xs: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(xs), q))


def warm_up(got: threading.Event, send) -> None:
    """Ping until the echo answers: the route through the router exists from then on."""
    for _ in range(100):
        got.clear()
        send()
        if got.wait(0.1):
            return
    raise RuntimeError("the echo process never answered")


#: Pings lost, by what was measured: a busy machine drops a 1 MiB message now and then (the
#: publishers drop rather than block, as the stack's streams do). A lost ping is sent again and
#: counted in the table, not taken for a dead echo.
LOST: dict[str, int] = {}


def ping_pong(got: threading.Event, send, n: int, what: str = "") -> list[float]:
    """Half round trips of `n` pings after 20 unmeasured ones, s; a ping unanswered in 2 s is
    counted in LOST and sent again, and more losses than pings means the echo is gone."""
    warm_up(got, send)
    out: list[float] = []
    lost = 0
    while len(out) < n + 20:
        got.clear()
        t = time.perf_counter()
        send()
        if not got.wait(2):
            lost += 1
            if lost > n + 20:
                raise RuntimeError(f"lost {lost} pings: the echo process stopped answering")
            warm_up(got, send)  # a late pong must not end the next ping's wait
            continue
        out.append((time.perf_counter() - t) / 2)
    LOST[what] = LOST.get(what, 0) + lost
    return out[20:]


def pubsub_ours(size: int, n: int) -> list[float]:
    """Bytes in an RgbImage; from 1 MiB up, a float32 DepthImage of that size (the array path)."""
    bus = Bus("bench")
    got = threading.Event()
    if size >= 1 << 20:
        bus.subscribe("bench/pong_depth", m.DepthImage, lambda msg: got.set())
        pub = bus.publisher("bench/ping_depth", m.DepthImage, express=True)
        depth = np.ones((size // 2048, 512), np.float32)
        make = lambda: m.DepthImage(depth=depth)  # noqa: E731
    else:
        bus.subscribe("bench/pong", m.RgbImage, lambda msg: got.set())
        pub = bus.publisher("bench/ping", m.RgbImage, express=True)
        payload = bytes(size)
        make = lambda: m.RgbImage(jpeg=payload, width=0, height=0)  # noqa: E731
    try:
        return ping_pong(got, lambda: pub.put(make()), n, "ours")
    finally:
        bus.close()


def pubsub_raw(endpoint: str, size: int, n: int, read: str = "") -> list[float]:
    """`read="bytes"`: the receiver copies the payload out (to_bytes), as the echo in raw-read
    mode; `read="array"`: a float32 array goes out (tobytes) and comes back (to_bytes, frombuffer),
    as the echo in raw-array mode."""
    s = zenoh.open(client_config(endpoint))
    got = threading.Event()
    if read == "bytes":
        sub = s.declare_subscriber("bench/rawpong", lambda sample: (sample.payload.to_bytes(), got.set()))
        pub = s.declare_publisher("bench/rawping", express=True)
    elif read == "array":
        sub = s.declare_subscriber("bench/arraypong", lambda sample: (
            np.frombuffer(sample.payload.to_bytes(), np.float32), got.set()))
        pub = s.declare_publisher("bench/arrayping", express=True)
    else:
        sub = s.declare_subscriber("bench/pong", lambda sample: got.set())
        pub = s.declare_publisher("bench/ping", express=True)
    if read == "array":
        depth = np.ones((size // 2048, 512), np.float32)
        send = lambda: pub.put(depth.tobytes())  # noqa: E731
    else:
        payload = bytes(size)
        send = lambda: pub.put(payload)  # noqa: E731
    try:
        return ping_pong(got, send, n, read or "raw")
    finally:
        sub.undeclare()
        s.close()


def paired_1mib(endpoint: str, n: int, rounds: int = 10) -> dict[str, list[float]]:
    """1 MiB pub/sub, ours and the two raw references, in alternating rounds with the three
    echoes running: the same pair of rows measured minutes apart differed by up to 40 %."""
    out: dict[str, list[float]] = {"ours": [], "bytes": [], "array": []}
    per = max(1, n // rounds)
    for _ in range(rounds):
        out["ours"] += pubsub_ours(1 << 20, per)
        for read in ("bytes", "array"):
            out[read] += pubsub_raw(endpoint, 1 << 20, per, read=read)
    return out


def rpc_ours(n: int) -> list[float]:
    with Bus("bench") as bus:
        out = []
        for i in range(n + 20):
            t = time.perf_counter()
            bus.call("bench/rpc", {"n": i}, timeout=2)
            if i >= 20:
                out.append(time.perf_counter() - t)
        return out


def rpc_raw(endpoint: str, n: int) -> list[float]:
    s = zenoh.open(client_config(endpoint))
    out = []
    payload = m.pack({"n": 1})
    for i in range(n + 20):
        t = time.perf_counter()
        replies = list(s.get("bench/rpc", payload=payload, timeout=2))
        assert replies and replies[0].ok is not None
        if i >= 20:
            out.append(time.perf_counter() - t)
    s.close()
    return out


def recorder_rate(n: int) -> tuple[float, int]:
    """Messages per second the recorder service writes to MCAP, fed by another process."""
    with tempfile.TemporaryDirectory() as d, Bus("recorder") as bus:
        svc = RecorderService(bus, Path(d))
        flood = spawn(FLOOD, str(n))
        assert flood.stdout.readline().strip() == "GO"
        t0 = t_last = time.perf_counter()
        last, still = -1, 0
        while svc.recorder.count < n and still < 300:
            time.sleep(0.01)
            count = svc.recorder.count
            if count == last:
                still += 1
            else:  # the rate is up to the last message written, not the 3 s spent seeing none come
                still, last, t_last = 0, count, time.perf_counter()
        elapsed = t_last - t0
        written = svc.recorder.count
        svc.close()
        flood.kill()
        return written / elapsed, n - written


def raw_receive_rate(endpoint: str, n: int) -> float:
    s = zenoh.open(client_config(endpoint))
    count = [0]
    done = threading.Event()

    def cb(sample):
        count[0] += 1
        if count[0] >= n:
            done.set()
    sub = s.declare_subscriber("bench/flood", cb)
    flood = spawn(FLOOD, str(n))
    assert flood.stdout.readline().strip() == "GO"
    t0 = time.perf_counter()
    done.wait(60)
    elapsed = time.perf_counter() - t0
    sub.undeclare()
    s.close()
    flood.kill()
    return count[0] / elapsed


def best_of(f, n: int, rounds: int = 5) -> float:
    """The best time of `rounds` rounds of `n` calls of f, per call, s (after one warm-up call)."""
    f()
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(n):
            f()
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def decode_times(n: int) -> tuple[float, float]:
    """Decoding a 1 MiB DepthImage, s: ours (the arrays are views onto the payload) and through
    msgpack's own path, which the decoder takes for anything but bytes (it copies each array)."""
    data = m.encode(m.DepthImage(depth=np.random.rand(512, 512).astype(np.float32), stamp=1))
    copied = bytearray(data)
    return best_of(lambda: m.decode(m.DepthImage, data), n), best_of(lambda: m.decode(m.DepthImage, copied), n)


def writer_rates(n: int) -> tuple[float, float]:
    """Small messages a second written to an in-memory MCAP file (zstd chunks of 1 MiB, indexed):
    the recorder's LeanWriter and the mcap library's Writer."""
    payload = m.encode(m.Battery(volts=12.0))

    def ours() -> None:
        w = LeanWriter(io.BytesIO())
        w.start("", "bench")
        c = w.register_channel("bench/battery", "msgpack")
        for i in range(n):
            w.add_message(c, i, payload, i)
        w.finish()

    def theirs() -> None:
        w = mcap.writer.Writer(io.BytesIO())
        w.start("", "bench")
        c = w.register_channel("bench/battery", "msgpack", 0)
        for i in range(n):
            w.add_message(c, i, payload, i)
        w.finish()
    return n / best_of(ours, 1, 3), n / best_of(theirs, 1, 3)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = ap.parse_args()
    n_small, n_big, n_rpc, n_flood = (5, 2, 5, 2000) if args.quick else (1000, 50, 1000, 200000)
    n_decode, n_write = (3, 2000) if args.quick else (300, 200000)
    rows = []
    with router() as endpoint:
        for mode in ("ours", "raw"):
            p = spawn(ECHO, mode, endpoint)
            assert p.stdout.readline().strip() == "READY"
            for size, n, label in ((64, n_small, "64 B"), (1024, n_small, "1 KiB"),
                                   (1 << 20, n_big, "1 MiB (512x512 float32 depth image)")):
                lat = pubsub_ours(size, n) if mode == "ours" else pubsub_raw(endpoint, size, n)
                rows.append((f"pub/sub latency {label}", mode, pct(lat, 50) * 1e6, pct(lat, 99) * 1e6))
            rtt = rpc_ours(n_rpc) if mode == "ours" else rpc_raw(endpoint, n_rpc)
            rows.append(("RPC round trip", mode, pct(rtt, 50) * 1e6, pct(rtt, 99) * 1e6))
            p.kill()
            p.wait()
        # zenoh-python hands a payload to Python only as a copy (ZBytes.to_bytes()), and the
        # raw echo above never takes one: this second reference does, on both sides.
        echoes = [spawn(ECHO, mode, endpoint) for mode in ("ours", "raw-read", "raw-array")]
        for p in echoes:
            assert p.stdout.readline().strip() == "READY"
        paired = {k: (pct(lat, 50) * 1e6, pct(lat, 99) * 1e6) for k, lat in paired_1mib(endpoint, n_big * 4).items()}
        for p in echoes:
            p.kill()
            p.wait()
        rate, dropped = recorder_rate(n_flood)
        raw_rate = raw_receive_rate(endpoint, n_flood)

    print("| what | value | unit | raw zenoh | ratio | budget |")
    print("|---|---|---|---|---|---|")
    by = {(w, mode): (p50, p99) for w, mode, p50, p99 in rows}
    for what in dict.fromkeys(w for w, *_ in rows):
        (o50, o99), (r50, r99) = by[(what, "ours")], by[(what, "raw")]
        budget = "p50 <= 1000, p99 <= 5000 (command path)" if "64 B" in what or "RPC" in what else ""
        print(f"| {what} p50 | {o50:.0f} | us | {r50:.0f} | {o50 / r50:.2f} | {budget} |")
        print(f"| {what} p99 | {o99:.0f} | us | {r99:.0f} | {o99 / r99:.2f} | |")
        if "1 MiB" in what:
            for read, how in (("bytes", "raw reading the payload (to_bytes)"),
                              ("array", "raw carrying the array (tobytes, to_bytes + frombuffer)")):
                for q, o, r in zip(("p50", "p99"), paired["ours"], paired[read]):
                    print(f"| {what} {q}, {how}, alternating rounds | {o:.0f} | us | {r:.0f} | {o / r:.2f} "
                          f"| {'<= 1.2x' if q == 'p50' else ''} |")
    print(f"| recorder sustained (bus -> MCAP, {n_flood} msgs) | {rate:.0f} | msg/s | {raw_rate:.0f} (receive only) "
          f"| {rate / raw_rate:.2f} | >= 100000 |")
    print(f"| recorder drops | {dropped} | msgs | | | 0 |")
    raw_lost = sum(v for k, v in LOST.items() if k != "ours")
    print(f"| pings lost and sent again (a busy machine drops some 1 MiB messages) | {LOST.get('ours', 0)} "
          f"| pings | {raw_lost} | | |")

    ours_us, msgpack_us = (t * 1e6 for t in decode_times(n_decode))
    lean, library = writer_rates(n_write)
    print()
    print("| in one process | ours | reference | the reference | ratio |")
    print("|---|---|---|---|---|")
    print(f"| decode a 1 MiB DepthImage (us) | {ours_us:.0f} | {msgpack_us:.0f} | msgpack's own path "
          f"(copies each array) | {ours_us / msgpack_us:.2f} |")
    print(f"| MCAP writer, {n_write} small messages (msg/s) | {lean:.0f} | {library:.0f} | mcap.writer.Writer "
          f"| {lean / library:.2f} |")


if __name__ == "__main__":
    main()
