"""Our messages as Foxglove JSON, for what no well-known Foxglove schema fits.

Foxglove decodes a JSON channel with the JSON schema it carries: `json_schema` builds it from
the message's dataclass, so a Plot or Raw Messages panel knows each field's type. `Json` is
such a message, ready for a channel; `plain` makes a value JSON can hold (bytes become
base64, as Foxglove's JSON encoding expects; arrays lists; NaN and infinities null).
"""

from __future__ import annotations

import base64
import dataclasses
import functools
import json
import math
import typing
from typing import Any

import msgpack
import numpy as np

from asibot.messages import REGISTRY, TYPE_FIELD

#: The schema of a message that names no type, or a type this version does not know.
UNTYPED = "untyped"


@dataclasses.dataclass(frozen=True)
class Json:
    """A message for a JSON channel: its JSON schema (its `title` names it) and its fields."""
    schema: dict
    body: dict

    @property
    def schema_name(self) -> str:
        return str(self.schema["title"])

    def encode(self) -> bytes:
        return json.dumps(plain(self.body), separators=(",", ":"), allow_nan=False).encode()


def _json_type(tp: Any) -> dict:
    """JSON schema of one dataclass field annotation."""
    origin = typing.get_origin(tp)
    if tp is float:
        return {"type": ["number", "null"]}      # NaN and infinities become null
    if tp is int:
        return {"type": "integer"}
    if tp is bool:
        return {"type": "boolean"}
    if tp is str:
        return {"type": "string"}
    if tp is bytes:
        return {"type": "string", "contentEncoding": "base64"}
    if tp is np.ndarray:
        return {"type": "array"}
    if origin is list:
        (item,) = typing.get_args(tp) or (Any,)
        return {"type": "array", "items": _json_type(item)}
    if origin is dict or tp is dict:
        return {"type": "object"}
    return {}


@functools.cache
def json_schema(type_name: str, fields: tuple[str, ...] | None = None, suffix: str = "") -> dict:
    """`asibot.<Type><suffix>`: the JSON schema of one of our message types (of only `fields`,
    when given), from its dataclass; a bare object schema for a type this version lacks."""
    title = f"asibot.{type_name}{suffix}"
    cls = REGISTRY.get(type_name)
    if cls is None:
        return {"title": title, "type": "object"}
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if fields is None or f.name in fields]
    return {"title": title, "type": "object", "properties": {n: _json_type(hints[n]) for n in names}}


def plain(v: Any) -> Any:
    """A JSON-ready copy: bytes -> base64, arrays -> lists, NaN/inf -> null."""
    if isinstance(v, dict):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, (bytes, bytearray, memoryview)):
        return base64.b64encode(bytes(v)).decode("ascii")
    if isinstance(v, np.ndarray):
        return plain(v.tolist())
    if isinstance(v, np.generic):
        return plain(v.item())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, msgpack.ExtType):
        return {"ext": v.code, "data": base64.b64encode(v.data).decode("ascii")}
    return v


def whole(type_name: str | None, body: Any) -> Json:
    """A message of ours as it is: every field under its type's schema."""
    if type_name is None:
        return Json(json_schema(UNTYPED), body if isinstance(body, dict) else {"value": body})
    return Json(json_schema(type_name), {k: v for k, v in body.items() if k != TYPE_FIELD})


def extra(type_name: str, msg: dict, fields: tuple[str, ...]) -> Json:
    """The fields of a message that its well-known Foxglove schema has no place for, with its
    stamp (the well-known message has it as its timestamp)."""
    fields = (*fields, "stamp")
    return Json(json_schema(type_name, fields, ".extra"), {f: msg[f] for f in fields})
