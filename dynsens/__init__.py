"""dynsens: gradient-based design optimization of nonlinear dynamic systems.

Governing equation -> Newmark-beta time integration -> Newton-Raphson, run once for the
state and once more, with matrix right-hand sides, for the design sensitivities.
"""
import os as _os
import sys as _sys
from typing import TYPE_CHECKING as _TYPE_CHECKING

if _TYPE_CHECKING:  # pragma: no cover
    from . import study as _study

# The per-step matrices are small (mechanisms, chains) or sparse: a threaded BLAS only adds
# overhead and, on a busy machine, contention, and its sums then depend on the thread count.
# Parallelism in dynsens is across simulations (finite-difference columns, optimization
# starts).  Set the variables yourself to override.
_USER_SET_THREADS = "OPENBLAS_NUM_THREADS" in _os.environ
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")
if not _USER_SET_THREADS and "numpy" in _sys.modules:
    # numpy or scipy imported before dynsens read no variable: their OpenBLAS is told directly
    from ._blas_threads import single_threaded_openblas as _single_threaded_openblas
    _single_threaded_openblas()

__version__ = "0.1.0"

from .case.load import Case, load_case, load_case_dict  # noqa: E402
from .errors import CaseError, ConvergenceError, DynsensError, ModelError  # noqa: E402
from .simulation import SimulationResult, run_case  # noqa: E402
from .io.reader import Result, read_result  # noqa: E402
from .api import OptimizeResult, Simulation, check_gradients, simulate  # noqa: E402
from . import optimize  # noqa: E402  (the subpackage; calling it runs dynsens.api.optimize)


def read_study(path: "str | _os.PathLike[str]") -> "_study.StudyTable":
    """Read a ``dynsens study`` file: ``dynsens.read_study(path).to_dataframe()`` (see dynsens.study).

    Imported on use, so that ``import dynsens`` does not load the study package.
    """
    from .study import read_study as _read
    return _read(_os.fspath(path))


# The public API; everything else (dynsens.models, dynsens.timeloop.march, ...) may change between versions.
__all__ = ["Case", "CaseError", "ConvergenceError", "DynsensError", "ModelError", "OptimizeResult", "Result",
           "Simulation", "SimulationResult", "__version__", "check_gradients", "load_case", "load_case_dict",
           "optimize", "read_result", "read_study", "run_case", "simulate"]
