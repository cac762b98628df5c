"""Output paths: checked before a run, names kept inside their folder, files written atomically.

Every command checks where it will write before the first step (a run of hours must not be
lost to a typo in ``-o``), refuses to replace a file without ``--overwrite``, derives file
names from a case name only through :func:`safe_stem` (a name such as ``../x`` cannot leave
the output folder), and writes through :func:`atomic_path`: a temporary file in the same
folder, given the permissions the user's umask grants, renamed into place on success and
removed on any failure, Ctrl-C or SIGTERM.
"""
from __future__ import annotations

import contextlib
import os
import re
import tempfile
from pathlib import Path
from typing import Iterable, Iterator

from ..errors import DynsensError


class OutputExistsError(DynsensError, FileExistsError):
    """The output file exists and ``--overwrite`` was not given."""


class OutputPathError(DynsensError, OSError):
    """An output path cannot be written (folder missing or read-only, name too long, ...)."""


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_stem(name: str, limit: int = 100) -> str:
    """A file-name stem from ``name``: letters, digits, ``. _ -`` only, no leading dot, at most
    ``limit`` characters (so ``../../x`` becomes ``x`` inside the output folder)."""
    stem = _UNSAFE.sub("_", name).strip("._-")[:limit]
    return stem or "case"


def current_umask() -> int:
    """The process umask (read without changing it where /proc tells it)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


#: bytes that atomic_path's temporary name ".NAME.XXXXXXXX.tmp" adds to a file name
_TEMPORARY_EXTRA = len(".") + len(".") + 8 + len(".tmp")


def _check_lengths(path: Path, option: str) -> None:
    """Every part of ``path`` and the whole of it within the file system's limits (checked
    before anything looks the path up, which would fail with a traceback)."""
    root = Path("/") if path.is_absolute() else Path(".")
    name_max = _name_max(root)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise OutputPathError(f"{option}: expected folder and file names of at most {name_max} bytes, "
                                  f"found a name of {len(os.fsencode(part))} bytes in {str(path)[:80]}...")
    try:
        path_max = int(os.pathconf(root, "PC_PATH_MAX"))
    except (OSError, ValueError, AttributeError):
        path_max = 4096
    whole = len(os.fsencode(os.path.abspath(path))) + _TEMPORARY_EXTRA
    if whole >= path_max:
        raise OutputPathError(f"{option}: expected a path of fewer than {path_max - _TEMPORARY_EXTRA} bytes "
                              f"(the file system's limit), found {whole - _TEMPORARY_EXTRA} bytes")


def check_output_path(path: str | Path, overwrite: bool = False, *, option: str = "-o/--output") -> Path:
    """Raise unless ``path`` can be written as a file: not a folder, legal name, its folder a
    folder (created later if missing) that this user may write, not existing unless
    ``overwrite``.  Returns the path."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputPathError(f"{option}: expected a file name, found {str(path)!r}")
    _check_lengths(p, option)
    if p.is_dir():
        raise OutputPathError(f"{option}: expected a file, found the folder {p}")
    name_max = _name_max(_existing_ancestor(p.parent))
    if len(os.fsencode(p.name)) + _TEMPORARY_EXTRA > name_max:
        raise OutputPathError(f"{option}: expected a file name of at most {name_max - _TEMPORARY_EXTRA} bytes "
                              f"(the file system allows at most {name_max} bytes, and the temporary file "
                              f"written first adds {_TEMPORARY_EXTRA}), found {len(os.fsencode(p.name))} bytes")
    _check_folder(p.parent, option)
    if p.exists() and not overwrite:
        raise OutputExistsError(f"{p} exists: pass --overwrite to replace it")
    return p


def check_output_folder(folder: str | Path, files: Iterable[Path], overwrite: bool = False, *,
                        option: str = "-o/--output") -> Path:
    """Raise unless ``folder`` is (or can be made) a writable folder and none of ``files`` exists
    (unless ``overwrite``)."""
    d = Path(folder)
    _check_lengths(d, option)
    if d.exists() and not d.is_dir():
        raise OutputPathError(f"{option}: expected a folder, found the file {d}")
    _check_folder(d, option)
    existing = [str(f) for f in files if Path(f).exists()]
    if existing and not overwrite:
        raise OutputExistsError(f"{', '.join(existing)} exist{'s' if len(existing) == 1 else ''}: pass "
                                "--overwrite to replace")
    return d


def _existing_ancestor(folder: Path) -> Path:
    d = folder if str(folder) else Path(".")
    while not d.exists() and d != d.parent:
        d = d.parent
    return d


def _check_folder(folder: Path, option: str) -> None:
    anc = _existing_ancestor(folder)
    if not anc.is_dir():
        raise OutputPathError(f"{option}: expected {folder} to be a folder, but {anc} is a file")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise OutputPathError(f"{option}: expected a folder you may write, found {anc} read-only for you")
    _try_writing(folder, option)


def _try_writing(folder: Path, option: str) -> None:
    """Make the missing part of ``folder`` and an unnamed file in it, then remove what was made:
    the file system's own answer (a read-only mount, /proc, a full quota), which permission
    bits do not give (and never for root)."""
    missing = []
    d = folder if str(folder) else Path(".")
    while not d.exists() and d != d.parent:
        missing.append(d)
        d = d.parent
    made: list[Path] = []
    try:
        for m in reversed(missing):
            m.mkdir()
            made.append(m)
        with tempfile.TemporaryFile(dir=folder if str(folder) else "."):
            pass
    except OSError as exc:
        raise OutputPathError(f"{option}: expected a folder that can be created and written, found "
                              f"{folder} refused ({exc.strerror or exc})") from None
    finally:
        for m in reversed(made):
            with contextlib.suppress(OSError):
                m.rmdir()


@contextlib.contextmanager
def atomic_path(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success give it the umask's permissions and
    rename it into place, on any failure (also Ctrl-C, SIGTERM) remove it."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path} exists: pass --overwrite to replace it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:      # a folder the checks could not foresee (e.g. under /proc)
        raise OutputPathError(f"{path}: expected a folder that can be created and written, found "
                              f"{path.parent} refused ({exc.strerror or exc})") from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        # mkstemp creates 0600; a result file gets the user's normal permissions
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | Path, text: str, overwrite: bool = False) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path, overwrite) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
