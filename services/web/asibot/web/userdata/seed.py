"""The seed's user folder in and out: a zip of every user file for a backup or another machine,
and the import of an ASIBOT user's folder (ours or the seed's webInterface folder), zipped or not."""

from __future__ import annotations

import io
import stat
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from asibot.web.userdata.errors import NotFound, UserDataError
from asibot.web.userdata.folder import decode
from asibot.web.userdata.icons import MAX_ICON_BYTES
from asibot.web.userdata.names import quote
from asibot.web.userdata.points import parse_point
from asibot.web.userdata.programs import MAX_PROGRAM_BYTES, check_program, check_program_name
from asibot.web.userdata.tasks import MAX_TASK_BYTES, check_task_name, parse_task
from asibot.web.userdata.words import check_word

if TYPE_CHECKING:   # the folder's front imports this module
    from asibot.web.userdata import UserData

#: The seed's launcher images (served from its figure host) and the shipped icon each became.
SEED_ICONS = {"drinkwater.jpg": "drink.svg", "pickcan.jpg": "can.svg", "washface.jpg": "face.svg",
              "brushteeth.jpg": "teeth.svg", "home.png": "home.svg"}
#: Beyond these, a points.ini or words.ini is not a hand-made list any more.
MAX_LIST_BYTES = 1024 * 1024
#: Limits on an imported zip: a zip bomb is refused before it fills the disk or the memory.
MAX_ZIP_ENTRIES = 2000
MAX_ZIP_TOTAL = 64 * 1024 * 1024

IMAGE_EXTENSIONS = {".png", ".jpg", ".jpeg", ".gif", ".webp", ".svg"}
NOT_A_USER_FILE = "it is not a user file (points.ini, words.ini, *.py, *.task, images)"


@dataclass
class Skipped:
    """One thing an import left out, and why."""

    item: str
    reason: str


@dataclass
class ImportReport:
    """What an import of a seed folder did: imported items, skipped ones, and notes."""

    imported: list[str] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def export_zip(data: UserData) -> bytes:
    """The folder as a zip in the seed's layout; the versions and the trash stay behind. Task
    files keep our icon names (drink.svg)."""
    root = data.folder.root
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        paths = [root / "points.ini", root / "words.ini"]
        paths += [data.program_files.path(p) for p in data.programs()] + sorted(root.glob("*.task"))
        paths += [data.folder.icons_dir / i.name for i in data.icons() if not i.shipped]
        for path in paths:
            if path.is_file():
                z.writestr(path.relative_to(root).as_posix(), path.read_bytes())
    return buf.getvalue()


def import_zip(data: UserData, zipped: bytes) -> ImportReport:
    """Load a zipped user folder. A zip with an unsafe entry (absolute, '..', a link) or that
    unpacks too big is refused whole, before any write."""
    try:
        infos = (z := zipfile.ZipFile(io.BytesIO(zipped))).infolist()
    except (zipfile.BadZipFile, ValueError, OSError):
        raise UserDataError("The file is not a zip archive.") from None
    if len(infos) > MAX_ZIP_ENTRIES:
        raise UserDataError(f"The zip holds {len(infos)} entries; the limit is {MAX_ZIP_ENTRIES}.")
    for info in infos:
        parts = info.filename.replace("\\", "/").split("/")
        if parts[0] == "" or ".." in parts or ":" in parts[0] or "\x00" in info.filename:
            raise UserDataError(f"The zip entry {quote(info.filename)} points outside the folder; "
                                "the zip is refused.")
        if stat.S_ISLNK(info.external_attr >> 16):
            raise UserDataError(f"The zip entry {quote(info.filename)} is a link; the zip is refused.")
    infos = [i for i in infos if not i.is_dir()]
    # A zipped folder ("webInterface/points.ini"): its one top folder is dropped.
    tops = {i.filename.split("/", 1)[0] for i in infos}
    strip = len(tops) == 1 and tops != {"icons"} and all("/" in i.filename for i in infos)
    files: dict[str, bytes | None] = {}
    total = 0
    for info in infos:
        name = info.filename.split("/", 1)[1] if strip else info.filename
        limit = import_limit(name)
        if limit is None or info.file_size > limit:
            files[name] = None  # not a user file, or too big: skipped unread
            continue
        try:
            with z.open(info) as f:  # the declared size may lie: never read past the limit
                body = f.read(limit + 1)
        except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError):
            # zipfile stops at the declared size, so a lying entry fails its CRC here;
            # encrypted or exotic entries land here too.
            raise UserDataError(f"The zip entry {quote(info.filename)} cannot be read "
                                "(damaged, encrypted or not what it declares); the zip is refused.") from None
        total += len(body)
        if len(body) > limit or total > MAX_ZIP_TOTAL:
            raise UserDataError("The zip unpacks to more than its entries declare or to more than "
                                f"{MAX_ZIP_TOTAL // 2**20} MiB; it is refused.")
        files[name] = body
    return _import(data, files)


def import_folder(data: UserData, path: Path) -> ImportReport:
    """Load an existing user folder. Links are not followed, so the import reads only what is
    in the folder."""
    path = Path(path)
    if not path.is_dir():
        raise NotFound(f"There is no folder {quote(str(path))}.")
    entries = list(path.iterdir())
    if (path / "icons").is_dir() and not (path / "icons").is_symlink():
        entries += list((path / "icons").iterdir())
    if len(entries) > MAX_ZIP_ENTRIES:
        raise UserDataError(f"The folder holds {len(entries)} files; the limit is {MAX_ZIP_ENTRIES}. "
                            "Is it the user folder?")
    files: dict[str, bytes | None] = {}
    for p in entries:
        if p.is_file() and not p.is_symlink():
            limit = import_limit(p.relative_to(path).as_posix())
            files[p.relative_to(path).as_posix()] = (
                None if limit is None or p.stat().st_size > limit else p.read_bytes())
    return _import(data, files)


def _import(data: UserData, files: dict[str, bytes | None]) -> ImportReport:
    """Import a user folder's files (None: unread, not ours or too big): points, words,
    programs, icons, then the tasks that need them. Each item is checked on its own: a
    bad one is skipped with its reason and the rest still load."""
    report = ImportReport()

    def text_of(name: str) -> str:
        text, latin = decode(files.pop(name) or b"")
        if latin:
            report.notes.append(f"{name} was not UTF-8; it was read as Latin-1.")
        return text

    for name in sorted(n for n, body in files.items() if body is None):
        del files[name]
        why = "it is too big for its kind" if import_limit(name) else NOT_A_USER_FILE
        report.skipped.append(Skipped(name, why))

    if "points.ini" in files:
        points = {p.name: p for p in data.points()}
        for number, line in enumerate(text_of("points.ini").splitlines(), 1):
            try:
                if line.strip():
                    p = parse_point(line)
                    points.pop(p.name, None)  # a later line of the same name wins, as on the seed
                    points[p.name] = p
                    report.imported.append(f"point {p.name}")
            except UserDataError as e:
                report.skipped.append(Skipped(f"points.ini line {number}", str(e)))
        data.point_file.write(list(points.values()))

    if "words.ini" in files:
        words = []
        for number, line in enumerate(text_of("words.ini").splitlines(), 1):
            try:
                if line.strip():
                    words.append(check_word(line))
                    report.imported.append(f"word {words[-1]}")
            except UserDataError as e:
                report.skipped.append(Skipped(f"words.ini line {number}", str(e)))
        data.word_file.add_new(words)

    for name in sorted(n for n in files if n.endswith(".py") and "/" not in n):
        try:
            program = check_program_name(name[:-3])
            text = text_of(name)
            existed = data.program_files.path(program).is_file()
            data.save_program(program, text)
            report.imported.append(f"program {program}" + (" (replaced; the old text is kept as a version)"
                                                           if existed else ""))
            errors = [p for p in check_program(text) if not p.message.startswith("Warning:")]
            if errors:
                report.notes.append(f"The program {program} does not compile in Python 3 (line {errors[0].line}: "
                                    f"{errors[0].message}); fix it in the Program tab.")
        except UserDataError as e:
            report.skipped.append(Skipped(name, str(e)))

    icon_names: dict[str, str] = {}  # an image's name in the imported folder -> its icon name here
    for name in sorted(n for n in files if Path(n).suffix.lower() in IMAGE_EXTENSIONS
                       and n.count("/") == n.startswith("icons/")):
        base, body = name.rsplit("/", 1)[-1], files.pop(name) or b""
        if base.lower() in SEED_ICONS:  # the seed's own launcher image: our icon stands in
            report.skipped.append(Skipped(name, f"the shipped {SEED_ICONS[base.lower()]} stands in for it"))
            continue
        try:
            icon_names[base] = data.add_icon(base, body)
            report.imported.append(f"icon {icon_names[base]}")
        except UserDataError as e:
            report.skipped.append(Skipped(name, str(e)))

    for name in sorted(n for n in files if n.endswith(".task") and "/" not in n):
        try:
            t = parse_task(check_task_name(name[:-5]), text_of(name))
            icon = SEED_ICONS.get(t.icon.lower()) or icon_names.get(t.icon) or t.icon
            data.save_task(t.name, t.program, t.words, icon, t.robot)
            report.imported.append(f"task {t.name}")
            if icon != t.icon:
                report.notes.append(f"The task {t.name} shows {icon} for the seed's {t.icon}.")
        except UserDataError as e:
            report.skipped.append(Skipped(name, str(e)))

    for name in sorted(files):  # left over: a user file's name at the wrong place
        report.skipped.append(Skipped(name, NOT_A_USER_FILE))
    return report


def import_limit(name: str) -> int | None:
    """The largest file of this kind an import reads; None for a file it does not take."""
    suffix = Path(name).suffix.lower()
    if name in ("points.ini", "words.ini"):
        return MAX_LIST_BYTES
    if suffix in (".py", ".task") and "/" not in name:
        return MAX_PROGRAM_BYTES if suffix == ".py" else MAX_TASK_BYTES
    if suffix in IMAGE_EXTENSIONS and name.count("/") == name.startswith("icons/"):
        return MAX_ICON_BYTES
    return None
