"""``dynsens simulate``: primal + sensitivity run, results to HDF5, summary table."""
from __future__ import annotations

import sys

import click
import numpy as np

from ..case.load import load_case
from ..io.hdf5 import write_result
from ..simulation import run_case
from .main import cli
from .options import case_argument, overwrite_option, set_option


def format_summary(result, design_names) -> str:  # type: ignore[no-untyped-def]
    """Responses with gradients, then the run statistics, as plain text."""
    lines = [f"status: {result.status} ({result.message})", "",
             f"{'response':<16}{'value':>16}  {'unit':<8}gradient d/d[{', '.join(design_names)}]"]
    for name, r in result.responses.items():
        if r.missing:
            lines.append(f"{name:<16}{'missing':>16}  {r.unit:<8}{r.missing}")
            continue
        g = "-" if r.gradient is None else "[" + ", ".join(f"{v:.6g}" for v in np.real(r.gradient)) + "]"
        lines.append(f"{name:<16}{float(np.real(r.value)):>16.8g}  {r.unit:<8}{g}")
        lines += _aggregate_notes(r.extra)
    c = result.counters
    lines += ["", f"steps {c['steps']}, Newton iterations {c['newton_iterations']}, "
                  f"factorizations {c['factorizations']} (time-step matrix {c['step_factorizations']}), "
                  f"residual evaluations {c['residual_evaluations']} "
                  f"(+{c['sensitivity_residual_evaluations']} for sensitivities), "
                  f"solves {c['solves']} ({c['solve_columns']} right-hand sides), "
                  f"wall time {result.wall_time:.3f} s"]
    return "\n".join(lines)


def _aggregate_notes(extra: dict) -> list[str]:
    """A KS value's sampled extreme and gap bound, and its warning (empty for other responses)."""
    for key in ("sampled_max", "sampled_min"):
        if key in extra:
            notes = [f"{'':<16}{extra[key]:>16.8g}  {'':<8}{key.replace('_', ' ')} of the "
                     f"{extra['samples']} samples (KS over-estimate <= ln(N)/rho = {extra['ks_gap_bound']:.4g})"]
            return notes + ([f"{'':<16}warning: {extra['warning']}"] if "warning" in extra else [])
    return []


@cli.command()
@case_argument
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), required=True,
              help="HDF5 result file to write.")
@overwrite_option
@set_option
@click.option("--no-sensitivities", is_flag=True, help="Primal run only.")
def simulate(case_file: str, output: str, overwrite: bool, overrides: tuple[str, ...],
             no_sensitivities: bool) -> None:
    """Simulate CASE_FILE and write time histories, responses and gradients to OUTPUT."""
    from pathlib import Path

    from ..io.hdf5 import OutputExistsError
    if Path(output).exists() and not overwrite:
        raise OutputExistsError(f"{output} exists: pass --overwrite to replace it")
    case = load_case(case_file, overrides)
    n = case.plan.n_steps
    show = n >= 2000 and sys.stderr.isatty()
    with click.progressbar(length=n, label=f"simulating {case.name}", file=sys.stderr,
                           hidden=not show) as bar:
        last = [0]

        def progress(i: int, total: int) -> None:
            if i - last[0] >= 200:
                bar.update(i - last[0])
                last[0] = i

        result = run_case(case, sensitivities=False if no_sensitivities else None, progress=progress)
    write_result(output, result, case, overwrite=overwrite)
    click.echo(format_summary(result, case.design_names))
    click.echo(f"written: {output}")
