"""The HTTP port's access token and the user's own copy of the AsTeRICS-Grid keyboards.

The bridge's HTTP port is on 127.0.0.1, which every program of this machine (and, without the
bridge's Origin check, every web page the user visits) can reach; its token is what the user's
own grids carry and nobody else knows. It is made once, kept in the user's data folder
(`<data>/asterics/token`, a 0700 folder, the file 0600, written whole: asibot.files) like the
web page's LAN token, and printed once, when it is made. The keyboards the bridge ships
(`setups/asibot-robot.grd.json`) cannot know it, so the bridge writes the user's copy, with the
token in every HTTP action (AsTeRICS-Grid's `authUser`/`authPw`: Basic auth), beside it:
`<data>/asterics/asibot-robot.grd.json`, the file to import.

    python -m asibot.asterics_bridge.http_token      # prints the token and writes the copy
"""

from __future__ import annotations

import os
import secrets
import sys
from pathlib import Path

from asibot.files import data_dir, write_atomic

from asibot.asterics_bridge import grids
from asibot.asterics_bridge.servers import DEFAULT_HTTP_PORT

#: The user's grid file, beside the token.
GRIDS_NAME = "asibot-robot.grd.json"


def default_folder() -> Path:
    """`<data>/asterics`: the bridge's secrets and the user's grids (asibot.files.data_dir)."""
    return data_dir() / "asterics"


def _private_folder(folder: Path) -> Path:
    """`folder`, made if needed, readable by its owner only (it holds the token)."""
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    os.chmod(folder, 0o700)
    return folder


def ensure_token(folder: Path | None = None, renew: bool = False) -> tuple[str, bool]:
    """The HTTP token kept in `folder` (default `default_folder()`), made on first use (or
    with `renew`), and whether it was just made: then, and only then, it is printed."""
    path = _private_folder(folder or default_folder()) / "token"
    if path.exists() and not renew:
        token = path.read_text().strip()
        if token:
            return token, False
    token = secrets.token_urlsafe(18)
    write_atomic(path, token.encode())       # mkstemp: 0600 from the start, then renamed
    os.chmod(path, 0o600)
    return token, True


def write_user_grids(token: str | None, url: str = grids.URL, folder: Path | None = None) -> Path:
    """The keyboards with this bridge's address and token in `folder`, 0600 (the token is in
    it); rewritten only when they differ, so an import in progress never reads half a file."""
    path = _private_folder(folder or default_folder()) / GRIDS_NAME
    text = grids.text(url=url, token=token).encode()
    if not path.exists() or path.read_bytes() != text:
        write_atomic(path, text)
    os.chmod(path, 0o600)
    return path


def main() -> int:
    port = int(os.environ.get("ASIBOT_ASTERICS_HTTP_PORT", DEFAULT_HTTP_PORT))
    token, _ = ensure_token()
    path = write_user_grids(token, f"http://127.0.0.1:{port}")
    print(f"The AsTeRICS bridge's HTTP token: {token}\n"
          f"AsTeRICS-Grid: import {path} (its buttons carry the token). "
          f"curl: curl -u :{token} -d forward http://127.0.0.1:{port}/command")
    return 0


if __name__ == "__main__":
    sys.exit(main())
