"""``dynsens simulate``: primal + sensitivity run, results to HDF5, summary table."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import click
import numpy as np

from ..case.load import load_case
from ..case.load_cases import has_load_cases, load_case_set_file, simulate_load_cases
from ..io.hdf5 import redundant_equations, write_load_case_results, write_result
from ..timeloop.progress import Progress
from ..io.paths import check_output_folder, check_output_path
from ..simulation import run_case
from .main import cli
from .options import (case_argument, default_output, overwrite_option, scheduler_option, set_option,
                      verbosity_options, workers_option)
from .views import DRAWN_HISTORIES, check_views, view_options, write_views

log = logging.getLogger("dynsens.cli")


def format_run_notes(result: Any) -> list[str]:
    """Step cuts and constraint drift (the per-step monitors), one line each when there are any."""
    lines = []
    if "rejected_steps" in result.counters:      # adaptive steps
        dt = np.diff(result.time)
        lines.append(f"adaptive steps: {dt.size} accepted, {result.counters['rejected_steps']} rejected, "
                     f"step sizes {dt.min():.3g} .. {dt.max():.3g} s" if dt.size else "adaptive steps: none")
    else:
        cuts = result.counters.get("step_cuts", 0)
        lines.append(f"step cuts: {cuts}" + (" (Newton failed on these steps; each was halved and retried)"
                                              if cuts else ""))
    for name, v in result.monitors.items():
        if len(v):
            lines.append(f"{monitor_label(name)}: max {float(np.max(np.abs(v))):.3g}, "
                         f"at the end {float(abs(v[-1])):.3g} (case units)")
    return lines


def monitor_label(name: str) -> str:
    """What a per-step monitor measures: the state's constraint drift, the sensitivities'
    constraint residual (J_Phi grad q + dPhi/dx), or the scale that residual is read against."""
    words = name.replace("_", " ")
    if name == "sensitivity_constraint_scale":
        return f"{words} (max |J_Phi grad q|)"
    return f"{words} residual" if name.startswith("sensitivity_constraint_") else f"{words} drift"


def format_summary(result: Any, design_names: tuple[str, ...]) -> str:
    """Responses with gradients, then the run statistics, as plain text."""
    # a run stopped by its event says which one and when (the file's status stays "terminated")
    events = getattr(result, "events", {})
    head = f"status: {result.ended_by}" if events else f"status: {result.status} ({result.message})"
    lines = [head, "",
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
    lines += format_run_notes(result)
    if getattr(result, "method", ""):
        lines.append(f"derivatives: {result.method} ({result.method_reason})")
        if result.method == "adjoint":
            lines.append(f"backward sweep: {c['backward_solves']} transposed solves, "
                         f"{c['backward_residual_evaluations']} residual evaluations for the design "
                         f"partials, {c['backward_output_evaluations']} output evaluations, "
                         f"{c['recomputed_steps']} recomputed steps")
    return "\n".join(lines)


def zero_gradient_columns(result, design_names) -> list[str]:  # type: ignore[no-untyped-def]
    """Design variables whose gradient entry is exactly zero for every response with a gradient."""
    grads = [np.real(r.gradient) for r in result.responses.values() if r.gradient is not None and not r.missing]
    if not grads:
        return []
    g = np.vstack(grads)
    return [n for j, n in enumerate(design_names) if j < g.shape[1] and not np.any(g[:, j])]


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
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
              help="HDF5 result file to write [default: results/<case name>.h5].")
@overwrite_option
@set_option
@click.option("--no-sensitivities", is_flag=True, help="Primal run only.")
@click.option("--plots", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Write a PNG of the recorded quantities (output.quantities) with units, events and "
                   "the responses that read them to DIR.")
@view_options
@workers_option("1")
@scheduler_option
@verbosity_options
def simulate(case_file: str, output: str | None, overwrite: bool, overrides: tuple[str, ...],
             no_sensitivities: bool, plots: str | None, vtk: str | None, vtk_every: int,
             animation: str | None, workers: int | None, scheduler: str | None) -> None:
    """Simulate CASE_FILE and write time histories, responses and gradients to OUTPUT.

    A case with load_cases runs each load case (in parallel with --workers or --scheduler)
    and writes each one's run under /load_cases/NAME of OUTPUT."""
    if output is not None:
        check_output_path(output, overwrite)     # before the case is read and run
    if has_load_cases(case_file):
        drawn = [opt for opt, v in (("--plots", plots), ("--vtk", vtk), ("--animation", animation)) if v]
        if drawn:
            raise click.UsageError(f"{', '.join(drawn)}: not available for a case with load_cases yet "
                                   f"({case_file}); simulate one load case with --set instead")
        simulate_load_case_set(case_file, output, overwrite, overrides, no_sensitivities, workers, scheduler)
        return
    case = load_case(case_file, overrides)
    if output is None:
        output = default_output(case, ".h5")
        check_output_path(output, overwrite)     # before the run, not after it
    if plots:
        check_output_folder(plots, [Path(plots) / f"{Path(output).stem}.png"], overwrite, option="--plots")
    check_views(output, [""], vtk, animation, overwrite)
    # a drawing reads the state histories: store them too (the case's own are kept)
    history = tuple(dict.fromkeys(tuple(case.plan.history) + DRAWN_HISTORIES)) if vtk or animation else None
    log.info("case %s: %d steps of %g s, %d design variables, %d responses, %d recorded quantities",
             case.name, case.plan.n_steps, case.plan.dt, len(case.design), len(case.response_names),
             len(case.quantities))
    with Progress(case.plan.n_steps, f"simulating {case.name}") as bar:
        result = run_case(case, sensitivities=False if no_sensitivities else None, history=history,
                          progress=lambda i, n: bar.update(i, f"step {i} of {n}"))
    write_result(output, result, case, overwrite=overwrite)
    click.echo(format_summary(result, case.design_names))
    if plots:
        from ..plots import Run, plot_runs, response_markers
        p = plot_runs([Run(case.name, result.quantities, result.events)], Path(plots) / f"{Path(output).stem}.png",
                      f"{case.name}: {getattr(result, 'ended_by', result.message)}",
                      response_markers(case, result))
        click.echo(f"plot: {p}" if p else "plots: the case records no quantities (add output.quantities)")
    if "sensitivity_constraint_position" in result.monitors:
        mon = result.monitors
        click.echo(f"constraint residual of the sensitivities (J_Phi grad q + dPhi/dx): position max "
                   f"{mon['sensitivity_constraint_position'].max():.3g}, velocity max "
                   f"{mon['sensitivity_constraint_velocity'].max():.3g} (scale max |J_Phi grad q| "
                   f"{mon['sensitivity_constraint_scale'].max():.3g}); state drift max "
                   f"{mon['constraint_position'].max():.3g}")
    dropped = redundant_equations(case.model)
    if dropped:
        click.echo(f"redundant joint equations left out of Phi: {', '.join(dropped)} (which ones follows the joints' "
                   "order in the file; the motion does not depend on it)")
        dependent = ", ".join(getattr(case.model, "dependent_joints", []))
        click.echo(f"reactions of the dependent joints {dependent}: the minimum-norm "
                   "multipliers over all their equations, the same for any order of the joints (docs/multibody.md, "
                   "\"redundant joints\")")
    zero = zero_gradient_columns(result, case.design_names)
    if zero:
        click.echo(f"note: the gradient with respect to {', '.join(zero)} is exactly zero for every response "
                   "(nothing in the model or responses depends on it at this design)")
    click.echo(f"written: {output}")
    write_views(output, vtk, animation, overwrite, vtk_every)


def simulate_load_case_set(case_file: str, output: str | None, overwrite: bool, overrides: tuple[str, ...],
                           no_sensitivities: bool, workers: int | None, scheduler: str | None) -> None:
    """``simulate`` of a case with load cases: every load case, one HDF5 group each."""
    from ..executor import make_executor
    cases = load_case_set_file(case_file, overrides)
    if output is None:
        output = default_output(cases, ".h5")
        check_output_path(output, overwrite)
    log.info("case %s: %d load cases (%s)", cases.name, len(cases.cases), ", ".join(cases.cases))
    with make_executor(workers, scheduler, tasks=len(cases.cases), default_workers=1) as ex:
        click.echo(f"simulating {len(cases.cases)} load cases of {cases.name}"
                   + (f" on {ex.description}" if getattr(ex, "description", "") else ""))
        results = simulate_load_cases(cases, sensitivities=False if no_sensitivities else None, executor=ex)
    write_load_case_results(output, results, cases, overwrite=overwrite)
    for name, result in results.items():
        click.echo(f"\nload case {name}:")
        click.echo(format_summary(result, cases.design_names))
    click.echo(f"\nwritten: {output} (one group per load case: /load_cases/NAME)")
