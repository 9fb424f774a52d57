"""Helpers shared by the recording tests."""

from __future__ import annotations

from typing import Any, Callable

import pytest


@pytest.fixture
def calls(monkeypatch) -> Callable[[Any, str], list[tuple]]:
    """`calls(module, "name")` wraps that function for the test and returns the list of the
    arguments of every call to it, to tell how much a piece of code did (or how far it got)."""

    def watch(owner: Any, name: str) -> list[tuple]:
        seen: list[tuple] = []
        real = getattr(owner, name)

        def counting(*args: Any) -> Any:
            seen.append(args)
            return real(*args)

        monkeypatch.setattr(owner, name, counting)
        return seen

    return watch
