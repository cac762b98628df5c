"""One BLAS thread whatever the import order (dynsens/_blas_threads.py).

``import dynsens`` sets OPENBLAS_NUM_THREADS=1 for libraries loaded after it; numpy and scipy
imported before it had started their OpenBLAS threads already, and a run's last bits — and an
optimizer's path with them — depended on the import order: the lightweight truss's optimum moved
by 2e-5 (relative) when numpy, scipy and OpenMDAO were imported first on a 2-core machine.
Each check runs in a fresh interpreter without the thread variables set.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dynsens._blas_threads import loaded_openblas

REPO = Path(__file__).resolve().parent.parent
TRUSS = REPO / "cases" / "truss_lightweight.yaml"

needs_openblas = pytest.mark.skipif(not loaded_openblas(), reason="no OpenBLAS loaded (another BLAS, or not Linux)")


def _python(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                               "MKL_NUM_THREADS")}
    clean.update(env)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=clean, cwd=REPO,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


THREADS = "import json; from dynsens._blas_threads import openblas_threads; print(json.dumps(openblas_threads()))"


@needs_openblas
def test_openblas_loaded_before_dynsens_is_set_to_one_thread():
    threads = json.loads(_python("import numpy, scipy.linalg\nimport dynsens\n" + THREADS))
    assert threads and set(threads.values()) == {1}, threads


@needs_openblas
def test_the_users_thread_count_is_kept():
    threads = json.loads(_python("import numpy, scipy.linalg\nimport dynsens\n" + THREADS, OPENBLAS_NUM_THREADS="2"))
    assert threads and set(threads.values()) == {2}, threads


@needs_openblas
def test_an_optimum_does_not_depend_on_the_import_order(tmp_path):
    """The lightweight truss optimized with dynsens imported first, and after numpy and scipy:
    the same design bit for bit."""
    run = ("import dynsens\nfrom dynsens.optimize.runner import optimize_case\n"
           f"out = optimize_case(dynsens.load_case({str(TRUSS)!r}), __import__('pathlib').Path({{!r}}), workers=1)\n"
           "print(out.best_outcome.x.tobytes().hex())")
    first = _python(run.format(str(tmp_path / "a.h5")))
    after = _python("import numpy, scipy.linalg, scipy.optimize\n" + run.format(str(tmp_path / "b.h5")))
    assert first == after
