"""Icons a task can show: the shipped SVGs (drawn by us), and images uploaded to icons/ (PNG,
JPEG, GIF, WebP; never SVG, which can carry scripts)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from asibot.files import write_atomic
from asibot.web.userdata.errors import NotFound, UserDataError
from asibot.web.userdata.folder import Folder
from asibot.web.userdata.names import MAX_NAME, need_str, quote

#: The icons that ship with the project (SVG, drawn by us, so safe to serve as images).
SHIPPED_ICONS = Path(str(resources.files("asibot.web") / "static" / "icons"))
MAX_ICON_BYTES = 2 * 1024 * 1024

ICON_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*\.(svg|png|jpg|gif|webp)")


@dataclass
class Icon:
    """An icon file name; shipped ones come with the project, the others were uploaded."""

    name: str
    shipped: bool


def check_icon_name(name: object) -> str:
    """An icon is a plain file name in one folder; anything else is refused."""
    name = need_str("icon name", name)
    if not ICON_RE.fullmatch(name):
        raise UserDataError(f"The icon name {quote(name)} is not an icon file name (like drink.svg).")
    return name


def image_kind(data: bytes) -> str | None:
    """The file extension an image really has, from its magic bytes; None if not one we take."""
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        return ".png"
    if data.startswith(b"\xff\xd8\xff"):
        return ".jpg"
    if data.startswith((b"GIF87a", b"GIF89a")):
        return ".gif"
    if len(data) >= 12 and data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return ".webp"
    return None


class Icons:
    """The shipped icons and one folder's uploaded ones."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def all(self) -> list[Icon]:
        """The shipped icons, then the uploaded ones."""
        shipped = sorted(p.name for p in SHIPPED_ICONS.glob("*.svg"))
        uploaded = sorted(p.name for p in self.folder.icons_dir.glob("*") if p.is_file() and ICON_RE.fullmatch(p.name)
                          and p.suffix != ".svg") if self.folder.icons_dir.is_dir() else []
        return [Icon(n, True) for n in shipped] + [Icon(n, False) for n in uploaded]

    def add(self, filename: str, data: bytes) -> str:
        """Store an uploaded image and return its icon name. The type comes from the bytes,
        not the name; SVG is refused since it can carry scripts."""
        if not isinstance(data, (bytes, bytearray)):
            raise UserDataError("The icon must be an image file.")
        if len(data) > MAX_ICON_BYTES:
            raise UserDataError(f"The image is {len(data) // 1024} KiB; the limit is {MAX_ICON_BYTES // 1024} KiB.")
        ext = image_kind(bytes(data))
        if ext is None:
            raise UserDataError(f"The file {quote(filename)} is not a PNG, JPEG, GIF or WebP image"
                                " (SVG is not taken: it can hold scripts).")
        stem = re.split(r"[/\\]", filename if isinstance(filename, str) else "")[-1].rsplit(".", 1)[0]
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", stem).strip("-_")[:MAX_NAME - 12] or "icon"
        icons_dir = self.folder.icons_dir
        icons_dir.mkdir(exist_ok=True)
        n, name = 1, stem + ext  # never .svg, so never a shipped icon's name
        while (icons_dir / name).exists():
            if (icons_dir / name).is_file() and (icons_dir / name).read_bytes() == data:
                return name  # the same image uploaded again
            n += 1
            name = f"{stem}-{n}{ext}"
        self.folder.room_for("icon", len(data))
        write_atomic(icons_dir / name, bytes(data))
        return name

    def file(self, name: str) -> Path:
        """The file of an icon, to serve it."""
        name = check_icon_name(name)
        # An SVG is served only if we drew it: one put in icons/ by hand could hold a script.
        path = (SHIPPED_ICONS if name.endswith(".svg") else self.folder.icons_dir) / name
        if path.is_file():
            return path
        raise NotFound(f"There is no icon named {quote(name)}.")
