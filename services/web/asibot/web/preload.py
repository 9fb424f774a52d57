"""The page's module graph, named up front: `<link rel="modulepreload">` for every module that
main.js imports, directly or not, so the browser asks for them all at once instead of finding
them one import at a time (as bundlers such as Vite write them). Dynamic `import()`s, the views
loaded when their tab is first shown, are left out: a page that never shows the 3D view never
fetches three.js."""

from __future__ import annotations

import re
from pathlib import Path, PurePosixPath

#: `import ... from '...'`, `export ... from '...'` and `import '...'`: the static imports only.
STATIC_IMPORT = re.compile(r"""(?:\b(?:import|export)\b[^'"`;()]*?\bfrom\s*|\bimport\s*)(['"])([^'"]+)\1""")
#: Comments, which may name an import that is not there.
COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)


def imports_of(source: str) -> list[str]:
    """The specifiers a module's source imports statically, in order."""
    return [m.group(2) for m in STATIC_IMPORT.finditer(COMMENT.sub("", source))]


class ModuleGraph:
    """The URLs of `entry`'s static imports under a folder served at `prefix`, read again only
    when a module of the graph changed (the files are served as written: edit and reload)."""

    def __init__(self, folder: Path, prefix: str, entry: str) -> None:
        self.folder, self.prefix, self.entry = folder, prefix.rstrip("/"), entry
        self._stamps: dict[Path, float] = {}
        self._urls: list[str] = []

    def urls(self) -> list[str]:
        if not self._stamps or any(_mtime(path) != stamp for path, stamp in self._stamps.items()):
            self._walk()
        return self._urls

    def _walk(self) -> None:
        stamps: dict[Path, float] = {}
        urls: list[str] = []
        todo = [PurePosixPath(self.entry)]
        while todo:
            relative = todo.pop(0)
            path = self.folder / relative
            if path in stamps:
                continue
            stamps[path] = _mtime(path)
            if relative != PurePosixPath(self.entry):
                urls.append(f"{self.prefix}/{relative}")
            try:
                source = path.read_text(encoding="utf-8")
            except OSError:
                continue       # a missing module: the browser says so when it imports it
            for specifier in imports_of(source):
                target = _served(relative, specifier, self.prefix)
                if target is not None:
                    todo.append(target)
        self._stamps, self._urls = stamps, urls


def _served(importer: PurePosixPath, specifier: str, prefix: str) -> PurePosixPath | None:
    """Where an import points in the served folder, or None if outside it (another site)."""
    if specifier.startswith(prefix + "/"):
        return PurePosixPath(specifier[len(prefix) + 1:])
    if specifier.startswith(("./", "../")):
        parts: list[str] = []
        for part in (importer.parent / specifier).parts:
            if part == "..":
                if not parts:
                    return None
                parts.pop()
            elif part != ".":
                parts.append(part)
        return PurePosixPath(*parts)
    return None


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return -1.0
