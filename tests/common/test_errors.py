"""RPC error codes: a code is one of errors.CODES, everywhere, or the program is wrong."""

import ast
from pathlib import Path

import pytest

from asibot.errors import CODES, RpcError

ROOT = Path(__file__).parents[2]


def test_an_unknown_code_is_a_programming_error():
    with pytest.raises(ValueError, match="unknown RPC error code 'unreachabel'"):
        RpcError("unreachabel", "The point is out of reach.")
    assert RpcError("unreachable", "The point is out of reach.").to_reply() == {
        "ok": False, "error": "unreachable", "message": "The point is out of reach."}


def raise_sites():
    """Every `RpcError("code", ...)` written with a literal code in the stack's source."""
    for path in sorted((ROOT / "libs").rglob("*.py")) + sorted((ROOT / "services").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == "RpcError"
                    and len(node.args) == 2 and isinstance(node.args[0], ast.Constant)):
                yield f"{path.relative_to(ROOT)}:{node.lineno}", node.args[0].value


def test_every_code_raised_in_the_source_is_known():
    sites = list(raise_sites())
    assert len(sites) > 20, "the scan found the raise sites"
    unknown = [(where, code) for where, code in sites if code not in CODES]
    assert not unknown, f"unknown RPC error codes: {unknown}"
