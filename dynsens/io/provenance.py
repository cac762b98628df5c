"""What produced a result file: versions, the checkout, the command, the host, the case's hash.

Every dynsens file carries these root attributes (written with the common header):

* ``provenance_versions``: JSON of python, dynsens, numpy, scipy, numba, h5py, click, pyyaml;
* ``provenance_git``: the commit of the checkout dynsens runs from (``+dirty`` when it has
  uncommitted changes), empty when it is not a checkout or git is missing;
* ``provenance_command``: the command line (``dynsens optimize ...``), or the script that called
  the Python API (``python script.py ...``);
* ``provenance_host``, ``provenance_timezone`` (the user's, with its UTC offset);
* ``case_sha256``: SHA-256 of the effective case text (after ``--set`` overrides), stored as
  ``case``: two files made from the same case have the same hash.
"""
from __future__ import annotations

import functools
import hashlib
import json
import platform
import shlex
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any

PACKAGES = ("numpy", "scipy", "numba", "h5py", "click", "pyyaml")


def versions() -> dict[str, str]:
    """Python's and the dependencies' versions (``missing`` for one not installed)."""
    from .. import __version__
    out = {"python": platform.python_version(), "dynsens": __version__}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "missing"
    return out


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """The commit of the checkout the package runs from, ``+dirty`` with uncommitted changes;
    empty when it is not a checkout (an installed wheel) or git is not there."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return ""
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""
    return head + ("+dirty" if dirty else "")


def command_line() -> str:
    """The command as the user typed it: ``dynsens ...`` for the console script, else the
    interpreter's arguments."""
    argv = list(sys.argv)
    if argv and Path(argv[0]).name in ("dynsens", "__main__.py"):
        argv[0] = "dynsens"
    elif argv:
        argv.insert(0, "python")
    return shlex.join(argv)


def case_sha256(case_text: str) -> str:
    """SHA-256 (hex) of the effective case text."""
    return hashlib.sha256(case_text.encode("utf-8")).hexdigest()


def provenance(case_text: str) -> dict[str, Any]:
    """The provenance attributes of a file made from ``case_text``."""
    return {"provenance_versions": json.dumps(versions(), sort_keys=True),
            "provenance_git": git_commit(),
            "provenance_command": command_line(),
            "provenance_host": socket.gethostname(),
            "provenance_timezone": time.strftime("%Z (UTC%z)"),
            "case_sha256": case_sha256(case_text)}
