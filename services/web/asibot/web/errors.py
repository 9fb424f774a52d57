"""How a refusal reaches the page: an HTTP status and `{"error": code, "message": sentence}`.

Robot refusals (`RpcError`, from the kinematics service or the drivers) and refusals of the
user's files (`UserDataError`) become 4xx answers whose sentence the page shows as it is;
FastAPI's validation errors are turned into one sentence that names the field.
"""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from asibot.errors import RpcError
from asibot.web.userdata import AlreadyExists, NotFound, UserDataError

#: HTTP status of each RPC error code; any other code is a conflict with the robot's state.
RPC_STATUS = {"bad_request": 400, "not_allowed": 403, "not_found": 404, "unavailable": 503, "timeout": 504, "internal": 500}


def refusal(status: int, code: str, message: str) -> JSONResponse:
    return JSONResponse({"error": code, "message": message}, status_code=status)


#: Parts of a pydantic error location that name a type of a union, not a field.
_UNION_TAGS = {"float", "int", "str", "bool", "list", "dict", "none", "literal"}


def field_sentence(exc: RequestValidationError) -> str:
    """The first validation problem as one sentence that names the field and what came:
    "values.0: Input should be a valid number (got 'a')." (one problem per field)."""
    problems: dict[str, dict] = {}
    for error in exc.errors():
        loc = [str(p) for p in error.get("loc", ()) if p not in ("body", "query", "path")]
        where = ".".join(p for p in loc if p.split("[")[0] not in _UNION_TAGS)
        problems.setdefault(where, error)
    if not problems:
        return "The request is not valid."
    where, first = next(iter(problems.items()))
    text = f"{where}: {first.get('msg', 'not valid')}" if where else first.get("msg", "not valid")
    if first.get("type") != "missing" and where:
        shown = repr(first.get("input"))
        text += f" (got {shown if len(shown) <= 40 else shown[:40] + '...'})"
    more = len(problems) - 1
    return text + (f"; and {more} more field{'s' * (more > 1)} like it." if more else ".")


def install(app: FastAPI) -> None:
    """Register the handlers that turn our exceptions into answers with a sentence."""

    @app.exception_handler(RpcError)
    async def rpc(request: Request, exc: RpcError) -> JSONResponse:
        return refusal(RPC_STATUS.get(exc.code, 409), exc.code, exc.message)

    @app.exception_handler(UserDataError)
    async def data(request: Request, exc: UserDataError) -> JSONResponse:
        status = 404 if isinstance(exc, NotFound) else 409 if isinstance(exc, AlreadyExists) else 400
        return refusal(status, "not_found" if status == 404 else "exists" if status == 409 else "bad_request", str(exc))

    @app.exception_handler(HTTPException)
    async def http(request: Request, exc: HTTPException) -> JSONResponse:
        # Starlette's own refusals (a body that is not JSON or nested too deep, an unknown path):
        # the same shape as ours, so the page shows a sentence.
        detail = exc.detail if isinstance(exc.detail, str) else "The request was refused."
        code = "not_found" if exc.status_code == 404 else "bad_request"
        if exc.status_code == 400:
            detail = detail.rstrip(".") + ": send the fields as one JSON object"
        return refusal(exc.status_code, code, detail.rstrip(".") + ".")

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return refusal(422, "bad_request", field_sentence(exc))
