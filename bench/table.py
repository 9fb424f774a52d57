"""The one table every benchmark prints (Markdown, so it pastes into a closing note)."""

from __future__ import annotations

from typing import Iterable, Sequence


def print_table(rows: Iterable[Sequence[object]],
                header: Sequence[str] = ("what", "value", "unit", "budget")) -> None:
    """Print `rows` under `header`; floats get three significant digits unless already text."""
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row) + " |")
