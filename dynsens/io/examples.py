"""The example cases shipped with dynsens, and copying them into a folder of the user's.

A wheel carries them as the package data folder ``dynsens/example_cases/`` (copied there from the
repository's ``cases/`` by the build, see setup.py); a source checkout or an editable install reads
``cases/`` beside the package.
"""
from __future__ import annotations

import shutil
from pathlib import Path

from ..errors import DynsensError
from .paths import OutputExistsError, OutputPathError, atomic_path, check_output_folder


class ExamplesNotFoundError(DynsensError):
    """Neither the packaged example cases nor a checkout's cases/ folder are present."""


def examples_folder() -> Path:
    """The folder of the shipped example cases: the wheel's package data, else the checkout's cases/."""
    here = Path(__file__).resolve().parents[1]     # the dynsens package (this module is in dynsens/io)
    for folder in (here / "example_cases", here.parent / "cases"):
        if folder.is_dir() and any(folder.glob("*.yaml")):
            return folder
    raise ExamplesNotFoundError(f"the example cases are missing: expected {here / 'example_cases'} (a wheel) "
                                f"or {here.parent / 'cases'} (a checkout); reinstall dynsens")


def example_files() -> list[Path]:
    """The shipped files, relative to :func:`examples_folder` (case files and what they use,
    e.g. ``records/``), sorted."""
    root = examples_folder()
    return sorted(p.relative_to(root) for p in root.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".h5")


def copy_examples(dest: str | Path, overwrite: bool = False) -> list[Path]:
    """Copy the example cases into the folder ``dest`` (made if missing); returns the written paths.

    Refuses, before writing anything, a ``dest`` that is a file and files that exist unless
    ``overwrite``.  Each file is written atomically.
    """
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise OutputPathError(f"DIR: expected a folder, found the file {dest}")
    root, files = examples_folder(), example_files()
    targets = [dest / f for f in files]
    clash = [t for t in targets if t.exists()]
    if clash and not overwrite:
        shown = ", ".join(str(t.relative_to(dest)) for t in clash[:3]) + (", ..." if len(clash) > 3 else "")
        raise OutputExistsError(f"{len(clash)} of the {len(files)} example files exist in {dest} ({shown}): "
                                "nothing was copied; pass --overwrite to replace them, or give another folder")
    for sub in sorted({t.parent for t in targets}):
        bad = next((a for a in (sub, *sub.parents) if a.exists() and not a.is_dir()), None)
        if bad is not None:
            raise OutputPathError(f"DIR: expected {sub} to be a folder, but {bad} is a file")
    check_output_folder(dest, [], overwrite, option="DIR")
    for f, t in zip(files, targets):
        with atomic_path(t, overwrite) as tmp:
            shutil.copyfile(root / f, tmp)
    return targets
