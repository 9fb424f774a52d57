"""The Program tab's Python reference: what a program can call on its clients, read from
asibot.client itself with `inspect` (its signatures and docstrings are the one source, so the
page never holds a copy that could fall behind).

`build()` answers GET /api/client-reference; the page shows it beside the editor and offers the
same methods as completions after `<name>.`.
"""

from __future__ import annotations

import functools
import inspect
import re
from typing import Any, Callable, Iterator

from asibot.client import CartesianClient, NavClient

#: The clients the reference describes: the arm's and the mobile base's.
CLIENTS: tuple[type, ...] = (CartesianClient, NavClient)
#: What a program does first and last with a client: listed before its other methods.
LIFECYCLE = ("open", "close")

#: Where a docstring's first sentence ends: a stop, then a capital letter starts the next one.
_SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=[A-Z])")


def build() -> dict[str, Any]:
    """{"module", "clients": [{"name", "doc", "methods": [{"name", "signature", "call",
    "returns", "summary", "doc"}]}]}: each client's public methods, base class first (open, close, the
    emergency stop), then its own in the order the source has them."""
    return _built()


@functools.cache
def _built() -> dict[str, Any]:
    return {"module": CartesianClient.__module__,
            "clients": [{"name": cls.__name__, "doc": first_paragraph(inspect.getdoc(cls)),
                         "methods": [method(name, fn) for name, fn in methods(cls)]} for cls in CLIENTS]}


def methods(cls: type) -> Iterator[tuple[str, Callable[..., Any]]]:
    """The methods a program calls on an instance of `cls`: public, not class or static methods
    (`on` makes a client for a service, over the service's bus), an override where there is one;
    connecting and closing first, then the bases' methods before the client's own."""
    found: dict[str, Callable[..., Any]] = {}
    for klass in reversed(cls.__mro__):
        for name, value in vars(klass).items():
            if not name.startswith("_") and name not in found and inspect.isfunction(value):
                found[name] = getattr(cls, name)
    first = [n for n in LIFECYCLE if n in found]
    for name in first + [n for n in found if n not in LIFECYCLE]:
        yield name, found[name]


def method(name: str, fn: Callable[..., Any]) -> dict[str, str]:
    """One method: its signature with types (`movl(point: Sequence[float], *, ...) -> float`),
    its call without them (`movl(point, *, duration=None, speed=None)`), what it returns
    (`float`), the first sentence of its docstring and the first paragraph."""
    doc = first_paragraph(inspect.getdoc(fn))
    returns = inspect.signature(fn).return_annotation
    return {"name": name, "signature": name + signature(fn, typed=True), "call": name + signature(fn, typed=False),
            "returns": "" if returns is inspect.Signature.empty else _annotation(returns),
            "summary": _SENTENCE_END.split(doc, maxsplit=1)[0], "doc": doc}


def signature(fn: Callable[..., Any], *, typed: bool) -> str:
    """`(point: Sequence[float], *, speed: float | None = None) -> float` without `self`; the
    annotations as the source writes them (the module postpones them, so they are strings)."""
    sig = inspect.signature(fn)
    parts: list[str] = []
    star = False
    for p in list(sig.parameters.values())[1:]:    # `self`
        if p.kind is p.KEYWORD_ONLY and not star:
            parts.append("*")
        star = star or p.kind in (p.KEYWORD_ONLY, p.VAR_POSITIONAL)
        text = ("*" if p.kind is p.VAR_POSITIONAL else "**" if p.kind is p.VAR_KEYWORD else "") + p.name
        annotated = typed and p.annotation is not p.empty
        if annotated:
            text += f": {_annotation(p.annotation)}"
        if p.default is not p.empty:
            text += f" = {p.default!r}" if annotated else f"={p.default!r}"
        parts.append(text)
    returns = f" -> {_annotation(sig.return_annotation)}" if typed and sig.return_annotation is not sig.empty else ""
    return f"({', '.join(parts)}){returns}"


def guess(client: str, missing: str) -> list[str]:
    """The methods of `client` a program may have meant by the `missing` name: those that have
    every word of it (up to two) in their name or summary, the most first (`open_gripper`: act,
    grip). None when no method has them, or too many do."""
    words = [w for w in missing.lower().split("_") if len(w) > 2]
    scores: dict[str, int] = {}
    for cls in CLIENTS:
        if cls.__name__ != client:
            continue
        for name, fn in methods(cls):
            summary = method(name, fn)["summary"].lower()
            scores[name] = sum(w == name or bool(re.search(rf"\b{re.escape(w)}\b", summary)) for w in words)
    best = max(scores.values(), default=0)
    found = [name for name, score in scores.items() if score == best and best >= min(2, len(words)) > 0]
    return found if len(found) <= 3 else []


def first_paragraph(doc: str | None) -> str:
    """The docstring's first paragraph on one line."""
    return " ".join((doc or "").strip().split("\n\n", 1)[0].split())


def _annotation(annotation: Any) -> str:
    return annotation if isinstance(annotation, str) else inspect.formatannotation(annotation)
