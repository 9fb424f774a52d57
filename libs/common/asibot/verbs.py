"""One way to declare an RPC verb: what it accepts, checked in one place, in one set of sentences.

A service declares its verbs as a table, verb -> `Verb` (its fields, each a `Field` with a
validator), and serves exactly that table with `serve`: each handler receives the checked
arguments (a namespace), never the raw map, so a verb cannot be served unchecked and a verb
without a handler (or a handler without a verb) is a start-up error, not a silent gap.

Any wrong type, size or value becomes `bad_request` with a sentence that names the field,
says what it must be (with the allowed range) and quotes at most a short prefix of what came
(`shown`): a megabyte of bad input never comes back in a reply. An unknown field is refused
(a typo such as 'sped' must not move the arm at the default speed).

The same tables describe the verbs to people: `Verb.describe` is the one line a command line
or a page shows for a verb.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Callable, Mapping, TypeGuard

import numpy as np

from asibot.errors import RpcError, quote

if TYPE_CHECKING:
    from asibot.bus import Bus
    from asibot.bus.base import Closable


class Invalid(Exception):
    """A validator's refusal: `detail` says what exactly is wrong (or "")."""

    def __init__(self, detail: str = "") -> None:
        super().__init__(detail)
        self.detail = detail


#: Longer lists, strings and bytes are shown from a prefix (no megabyte repr to cut).
_LONG = 64


def shown(value: object) -> str:
    """`errors.quote(value)`, safe and cheap for anything a request can carry: a long list,
    string or bytes is shown from its first elements with its length, and a list nested a
    thousand deep (which has no repr) by its type."""
    try:
        if isinstance(value, (list, tuple, str, bytes)) and len(value) > _LONG:
            unit = "characters" if isinstance(value, str) else "bytes" if isinstance(value, bytes) else "elements"
            return f"{quote(value[:_LONG])[:60]}... ({len(value)} {unit})"
        return quote(value)
    except RecursionError:
        return f"a {type(value).__name__} nested too deep to show"


def _real(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _g(x: float) -> str:
    return f"{x:g}"


@dataclass(frozen=True)
class Number:
    """A finite real number in [lo, hi] (or (lo, hi] with `open_low`), `unit` for the sentence."""

    lo: float
    hi: float
    unit: str = ""
    open_low: bool = False

    def range(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.open_low else '['}{_g(self.lo)}, {_g(self.hi)}]{unit}"

    def describe(self) -> str:
        return f"a number in {self.range()}"

    def __call__(self, value: object) -> float:
        # Compare before converting: an int of any size compares exactly with a float.
        if not _real(value) or (isinstance(value, float) and not math.isfinite(value)):
            raise Invalid()
        if not (self.lo < value if self.open_low else self.lo <= value) or not value <= self.hi:
            raise Invalid()
        return float(value)


@dataclass(frozen=True)
class Numbers:
    """A list (or 1-D numeric array) of len(names) numbers, element i checked by parts[i]."""

    names: tuple[str, ...]
    parts: tuple[Number, ...]

    def describe(self) -> str:
        groups: list[tuple[list[str], Number]] = []
        for name, part in zip(self.names, self.parts):
            if groups and groups[-1][1] == part:
                groups[-1][0].append(name)
            else:
                groups.append(([name], part))
        ranges = "; ".join(f"{', '.join(names)} in {part.range()}" for names, part in groups)
        return f"[{', '.join(self.names)}], {len(self.names)} finite numbers ({ranges})"

    def __call__(self, value: object) -> np.ndarray:
        if isinstance(value, np.ndarray):
            if value.ndim != 1 or value.dtype.kind not in "iuf":
                raise Invalid()
            if len(value) != len(self.names):
                raise Invalid(f"it has {len(value)} elements")
            value = value.tolist()
        if not isinstance(value, (list, tuple)):
            raise Invalid()
        if len(value) != len(self.names):  # before looking inside: a long list costs nothing
            raise Invalid(f"it has {len(value)} elements")
        out = np.empty(len(value))
        for i, (name, part, v) in enumerate(zip(self.names, self.parts, value)):
            try:
                out[i] = part(v)
            except Invalid:
                what = f"outside {part.range()}" if _real(v) and not (isinstance(v, float) and math.isnan(v)) \
                    else "not a finite number"
                raise Invalid(f"{name} = {shown(v)} is {what}") from None
        return out


@dataclass(frozen=True)
class OneOf:
    """One of a few words."""

    choices: tuple[str, ...]

    def describe(self) -> str:
        return " or ".join(self.choices)

    def __call__(self, value: object) -> str:
        if not isinstance(value, str) or value not in self.choices:
            raise Invalid()
        return value


@dataclass(frozen=True)
class Flag:
    def describe(self) -> str:
        return "true or false"

    def __call__(self, value: object) -> bool:
        if not isinstance(value, bool):
            raise Invalid()
        return value


@dataclass(frozen=True)
class Whole:
    """A whole number in [lo, hi]: an int, not a float (a level is counted, not measured) nor a
    bool (JSON's `true` is not the number 1 here)."""

    lo: int
    hi: int

    def describe(self) -> str:
        return f"a whole number from {self.lo} to {self.hi}"

    def __call__(self, value: object) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or not self.lo <= value <= self.hi:
            raise Invalid()
        return value


@dataclass(frozen=True)
class Text:
    """A string of 1 to `longest` characters (after stripping blanks at its ends: a name of
    spaces is no name). `what` says what it is, e.g. "a place name"."""

    what: str = "a text"
    longest: int = 200

    def describe(self) -> str:
        return f"{self.what} of 1 to {self.longest} characters"

    def __call__(self, value: object) -> str:
        if not isinstance(value, str) or not value.strip():
            raise Invalid()
        if len(value) > self.longest:
            raise Invalid(f"it has {len(value)} characters")
        return value.strip()


@dataclass(frozen=True)
class Texts:
    """A list of at most `most` texts, each checked by `each`."""

    each: Text
    most: int = 1000

    def describe(self) -> str:
        return f"a list of at most {self.most} items, each {self.each.describe()}"

    def __call__(self, value: object) -> list[str]:
        if not isinstance(value, (list, tuple)):
            raise Invalid()
        if len(value) > self.most:
            raise Invalid(f"it has {len(value)} items")
        out = []
        for i, v in enumerate(value):
            try:
                out.append(self.each(v))
            except Invalid:
                raise Invalid(f"item {i + 1}, {shown(v)}, is not {self.each.what}") from None
        return out


@dataclass(frozen=True)
class Blob:
    """Bytes (audio, an image), at most `largest` of them."""

    what: str = "bytes"
    largest: int = 16 << 20

    def describe(self) -> str:
        return f"{self.what}, at most {self.largest} bytes"

    def __call__(self, value: object) -> bytes:
        if not isinstance(value, (bytes, bytearray, memoryview)):
            raise Invalid()
        data = bytes(value)
        if len(data) > self.largest:
            raise Invalid(f"it has {len(data)} bytes")
        return data


@dataclass(frozen=True)
class Map:
    """A map of names to values whose meaning the handler checks field by field (a settings
    change); here only that it is a map with text keys and not too many of them."""

    what: str = "a map"
    most: int = 64

    def describe(self) -> str:
        return f"{self.what} (names to values)"

    def __call__(self, value: object) -> dict[str, Any]:
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise Invalid()
        if len(value) > self.most:
            raise Invalid(f"it has {len(value)} entries")
        return dict(value)


Validator = Number | Numbers | OneOf | Flag | Whole | Text | Texts | Blob | Map


@dataclass(frozen=True)
class Field:
    """One named argument. Absent and null are the same: `default` (None unless given), or
    a refusal when `required`."""

    check: Validator
    required: bool = False
    default: Any = None
    #: Said after what the value must be, e.g. "or null to remove it".
    also: str = ""

    def describe(self) -> str:
        return self.check.describe() + (f", {self.also}" if self.also else "")


@dataclass(frozen=True)
class Verb:
    """The arguments of one verb. `strict`: an unknown field is refused (a typo such as
    'sped' must not move the arm at the default speed); `stop` is not strict, because a stop
    always stops. `needs_driver`: the server waits a moment for the arm driver before it
    answers (just after start-up its first state may be behind the first request)."""

    fields: Mapping[str, Field] = field(default_factory=dict)
    strict: bool = True
    needs_driver: bool = False

    #: One line for people: what the verb does (a command line's help, a page's tooltip).
    doc: str = ""

    def parse(self, verb: str, request: object) -> SimpleNamespace:
        """The checked arguments (every field of the table, absent ones at their default),
        or RpcError("bad_request", sentence)."""
        if not isinstance(request, Mapping):
            raise RpcError("bad_request", f"{verb} takes a map of arguments; got {shown(request)}.")
        if self.strict:
            unknown = [k for k in request if k not in self.fields]
            if unknown:
                takes = f"takes only {', '.join(self.fields)}" if self.fields else "takes no arguments"
                raise RpcError("bad_request", f"{verb} {takes}; {shown(unknown[0])} is not one of them.")
        out = {}
        for name, f in self.fields.items():
            value = request.get(name)
            if value is None:
                if f.required:
                    raise RpcError("bad_request", f"{verb} needs '{name}': {f.describe()}.")
                out[name] = f.default
                continue
            try:
                out[name] = f.check(value)
            except Invalid as exc:
                why = f" ({exc.detail})" if exc.detail else ""
                raise RpcError("bad_request", f"'{name}' must be {f.describe()}; got {shown(value)}{why}.") \
                    from None
        return SimpleNamespace(**out)



    def describe(self, verb: str) -> str:
        """`verb(field: what it must be, ...)`, then the one line of `doc`."""
        args = ", ".join(f"{name}{'' if f.required else '?'}: {f.describe()}" for name, f in self.fields.items())
        return f"{verb}({args})" + (f": {self.doc}" if self.doc else "")


#: A verb's handler: the checked arguments in, the reply's fields out.
Handler = Callable[[Any], dict]


def check_table(table: Mapping[str, Verb], handlers: Mapping[str, Handler]) -> None:
    """ValueError unless every verb of `table` has a handler and every handler a verb."""
    missing, extra = sorted(set(table) - set(handlers)), sorted(set(handlers) - set(table))
    if missing or extra:
        raise ValueError(f"verbs without a handler: {missing or 'none'}; handlers without a verb: {extra or 'none'}")


def serve(bus: Bus, key_of: Callable[[str], str], table: Mapping[str, Verb], handlers: Mapping[str, Handler],
          *, before: Callable[[str, Verb, SimpleNamespace], None] | None = None) -> list[Closable]:
    """Serve every verb of `table` on `key_of(verb)`: the request is checked by its `Verb`,
    `before(verb, spec, args)` runs next (a wait for the driver, a refusal while another
    program holds the robot), then `handlers[verb](args)` answers."""
    check_table(table, handlers)

    def handler(verb: str, spec: Verb, handle: Handler) -> Callable[[dict], dict]:
        def run(request: dict) -> dict:
            args = spec.parse(verb, request)
            if before is not None:
                before(verb, spec, args)
            return handle(args)
        return run

    return [bus.serve(key_of(verb), handler(verb, spec, handlers[verb])) for verb, spec in table.items()]
