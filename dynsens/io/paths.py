"""Output paths: checked before a run, names kept inside their folder, files written atomically.

Every command checks where it will write before the first step (a run of hours must not be
lost to a typo in ``-o``), refuses to replace a file without ``--overwrite``, derives file
names from a case name only through :func:`safe_stem` (a name such as ``../x`` cannot leave
the output folder), and writes through :func:`atomic_path`: a temporary file in the same
folder, given the permissions the user's umask grants, renamed into place on success and
removed on any failure, Ctrl-C or SIGTERM.  A file that is appended to while a command runs
(an optimization's or a study's HDF5) has one writer at a time: :func:`writer_lock`.
"""
from __future__ import annotations

import contextlib
import fcntl
import functools
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, TypeVar

from ..errors import DynsensError


class OutputExistsError(DynsensError, FileExistsError):
    """The output file exists and ``--overwrite`` was not given."""


class OutputPathError(DynsensError, OSError):
    """An output path cannot be written (folder missing or read-only, name too long, ...)."""


class OutputLockedError(DynsensError, BlockingIOError):
    """Another process is writing the same output file."""


F = TypeVar("F", bound=Callable[..., Any])


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
#: bytes that writer_lock's lock file ".NAME.lock" adds to a file name
_LOCK_EXTRA = len(".") + len(".lock")


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
    _check_name_room(p, _TEMPORARY_EXTRA, "the temporary file written first", option)
    _check_folder(p.parent, option)
    if p.exists() and not overwrite:
        raise OutputExistsError(f"{p} exists: pass --overwrite to replace it")
    return p


def _check_name_room(p: Path, extra: int, what: str, option: str) -> None:
    """Raise unless the name of ``p`` with ``extra`` bytes more (a file made beside it) fits the
    file system's limit on names."""
    name_max = _name_max(_existing_ancestor(p.parent))
    n = len(os.fsencode(p.name))
    if n + extra > name_max:
        raise OutputPathError(f"{option}: expected a file name of at most {name_max - extra} bytes "
                              f"(the file system allows at most {name_max} bytes, and {what} "
                              f"adds {extra}), found {n} bytes")


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


# --------------------------------------------------------------------------------------
# one writer per output file
# --------------------------------------------------------------------------------------
def lock_path(path: str | Path) -> Path:
    """The lock file that guards ``path`` (hidden, in the same folder)."""
    p = Path(path)
    return p.with_name(f".{p.name}.lock")


@contextlib.contextmanager
def writer_lock(path: str | Path, *, option: str = "-o/--output") -> Iterator[None]:
    """Hold an exclusive lock on the output file ``path`` for the duration of the block.

    A second writer (another ``dynsens optimize`` or ``dynsens study`` with the same ``-o``,
    also ``--resume`` or ``--overwrite``) is refused at once with :class:`OutputLockedError`
    instead of interleaving its rows.  The lock is an ``flock`` on a hidden file beside
    ``path``, released by the kernel when the process ends (also on SIGKILL), and the file is
    removed on the way out.  A name too long for its lock file is an :class:`OutputPathError`.
    """
    p = Path(path)
    _check_lengths(p, option)                   # before anything looks the path up
    _check_name_room(p, _LOCK_EXTRA, "its lock file", option)
    lp = lock_path(p)
    lp.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lp, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputLockedError(f"{path} is being written by another dynsens process (lock {lp}): wait for "
                                    "it to finish, or write to another -o file") from None
        # the holder before us may have removed the file between our open and our lock
        try:
            same = os.stat(lp).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lp)
        os.close(fd)


def holds_writer_lock(fn: F) -> F:
    """Decorate ``fn(case, output, ...)`` to run under :func:`writer_lock` of ``output``."""
    @functools.wraps(fn)
    def wrapper(case: Any, output: str | Path, *args: Any, **kwargs: Any) -> Any:
        with writer_lock(output):
            return fn(case, output, *args, **kwargs)
    return wrapper  # type: ignore[return-value]
