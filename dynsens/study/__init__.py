"""Design studies: a case evaluated at many designs (``dynsens study``).

Designs come from ``--sample``: a Latin hypercube (``lhs:N``), scrambled Sobol' points
(``sobol:N``, N a power of 2), a full factorial grid (``grid:AxBx…``) in the case's bounds,
or a CSV file whose header names design variables.  Each design is an independent
simulation (values, and gradients with ``--gradients``, by the case's own sensitivity
method) run by :mod:`dynsens.executor`: local worker processes or a Dask cluster.

Output file (STUDY.h5, a row appended as each design finishes, in any order)
----------------------------------------------------------------------------
* root attributes as every dynsens file (``status``: running, completed or interrupted;
  ``message``); ``/design/{names, values (x0), lower, upper}``;
* ``/study`` attributes: ``sample``, ``seed`` (−1 if none), ``gradients``, ``n_designs``,
  ``response_names`` and ``response_units`` (JSON), ``runs`` (1 + number of resumes);
  ``/study/designs`` (N, m): every planned design;
* ``/study/rows/*``, one row per finished design: ``index`` (into ``designs``), ``x`` (m,),
  ``values`` (n_r,), ``gradients`` (n_r, m) with ``--gradients``, ``failed`` (the simulation
  raised), ``message`` (its error, or the missing responses and why), ``wall_time`` (s),
  ``run`` (0, +1 per ``--resume``), ``worker`` (host:pid).

Read it with :func:`read_study` (``.to_dataframe()`` with pandas installed).
"""
from __future__ import annotations

from .plots import format_summary, plot_study, sensitivity_summary
from .runner import DesignTask, evaluate_design, run_study
from .sampling import StudyError, read_designs_csv, sample_designs
from .store import StudyTable, read_study

__all__ = ["DesignTask", "StudyError", "StudyTable", "evaluate_design", "format_summary", "plot_study",
           "read_designs_csv", "read_study", "run_study", "sample_designs", "sensitivity_summary"]
