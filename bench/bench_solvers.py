"""Kinematic solver figures: closed-form single calls, batch throughput, Pinocchio per call.

Prints one markdown table. Budgets: asibot IK single call 10 us, batch IK 1 M poses/s (issue 3).

    python bench/bench_solvers.py [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from asibot import robots
from asibot.kinematics import AsibotSolver, GenericSolver
from asibot.kinematics.model import solver_for

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`


def per_call_us(fn, args: list, repeat: int = 3) -> float:
    """Best-of-repeat mean time per call over the argument list, in microseconds."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for a in args:
            fn(*a)
        best = min(best, (time.perf_counter() - t0) / len(args))
    return best * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    quick = ap.parse_args().quick
    # (single calls, batch poses, Pinocchio FK calls, Pinocchio IK calls, best of)
    singles, batch, fk, ik, best_of = (50, 1000, 5, 5, 1) if quick else (20000, 1_000_000, 300, 100, 3)
    rng = np.random.default_rng(0)
    s = AsibotSolver()
    q = rng.uniform(-1, 1, (singles, 5)) * [170, 120, 120, 120, 170]
    x = s.fwd_batch(q)
    ql, xl = q.tolist(), x.tolist()
    guess = [0.0] * 5
    rows = [
        ("closed-form IK, single call", per_call_us(s.inv, [(p, guess) for p in xl], best_of), "us", "10"),
        ("closed-form FK, single call", per_call_us(s.fwd, [(r,) for r in ql], best_of), "us", "-"),
    ]
    big_q = rng.uniform(-1, 1, (batch, 5)) * [170, 120, 120, 120, 170]
    big_x = s.fwd_batch(big_q)
    best = float("inf")
    for _ in range(best_of):
        t0 = time.perf_counter()
        _, ok = s.inv_batch(big_x, guess)
        best = min(best, time.perf_counter() - t0)
    rows.append((f"batch IK throughput ({len(big_x):,} poses)", len(big_x) / best / 1e6, "M poses/s", ">= 1"))
    t0 = time.perf_counter()
    s.fwd_batch(big_q)
    rows.append((f"batch FK throughput ({len(big_q):,} poses)", len(big_q) / (time.perf_counter() - t0) / 1e6, "M poses/s", "-"))
    for rid, name in (("asibot", "ASIBOT"), ("pioneer", "Katana")):
        spec = robots.get(rid)
        g = GenericSolver(spec.urdf_path, spec.tool_link, spec.joint_names)
        qs = rng.uniform(spec.lower, spec.upper, (fk, 5))
        rows.append((f"Pinocchio FK per call, {name}", per_call_us(g.fwd, [(r,) for r in qs], best_of), "us", "-"))
        m = solver_for(spec)
        targets = [m.fwd(r) for r in qs[:ik]]
        near = [(t, r + 0.05) for t, r in zip(targets, qs[:ik])]
        rows.append((f"Pinocchio IK per call from a near guess, {name}",
                     per_call_us(lambda t, gq: m.inv(t, np.clip(gq, spec.lower, spec.upper)), near, 1), "us", "-"))
    print_table(rows)


if __name__ == "__main__":
    main()
