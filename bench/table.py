"""The one table every benchmark prints (Markdown, so it pastes into a closing note)."""

from __future__ import annotations

import time
from typing import Callable, Iterable, Sequence

import numpy as np

#: The help of the one smoke-run flag every bench has; tests/bench runs each bench with it.
QUICK_HELP = "smoke run (CI): tiny sizes, few samples; it checks that the bench runs, its figures mean nothing"


def print_table(rows: Iterable[Sequence[object]],
                header: Sequence[str] = ("what", "value", "unit", "budget")) -> None:
    """Print `rows` under `header`; floats get three significant digits unless already text."""
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row) + " |")


def times(fn: Callable[[], object], runs: int, warmup: int = 1) -> np.ndarray:
    """Seconds taken by each of `runs` calls of `fn`, after `warmup` calls that are not counted."""
    for _ in range(warmup):
        fn()
    t = np.empty(runs)
    for i in range(runs):
        start = time.perf_counter()
        fn()
        t[i] = time.perf_counter() - start
    return t
