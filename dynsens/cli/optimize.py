"""``dynsens optimize``: SLSQP on the design sensitivities, history appended to HDF5 per iteration, and the
optimum's verification."""
from __future__ import annotations

import math
import sys
from typing import Any

import click
import numpy as np

from ..case.load_cases import LoadCaseSet, load_any_case
from ..optimize import FEAS_TOL, OptimizationError, OptimizationResult, StartOutcome, plot_optimization
from ..optimize.verified import optimize_verified
from ..optimize.verify_cases import AnyVerification, format_any_verification
from ..optimize.summary import decision_summary
from ..timeloop.progress import Progress
from .main import cli
from .options import (FiniteFloat, case_argument, default_output, overwrite_option, scheduler_option, seed_option,
                      set_option, verbosity_options)


def _parse_x0(ctx: Any, param: Any, values: tuple[str, ...]) -> dict[str, float]:
    """click callback: ('A=3', 'B=4.5') -> {'A': 3.0, 'B': 4.5}; every VALUE finite."""
    out: dict[str, float] = {}
    for item in values:
        name, sep, val = item.partition("=")
        try:
            if not sep or not name.strip() or not math.isfinite(float(val)):
                raise ValueError
            out[name.strip()] = float(val)
        except ValueError:
            raise click.BadParameter(f"expected NAME=VALUE with a finite number VALUE, found {item!r}") from None
    return out


SHOWN_VALUES = 12   # a longer design vector is shortened in the terminal (the file has it whole)


def _vec(v: Any) -> str:
    a = np.asarray(v, dtype=float)
    if a.size <= SHOWN_VALUES:
        return "[" + ", ".join(f"{x:.6g}" for x in a) + "]"
    head = ", ".join(f"{x:.6g}" for x in a[:SHOWN_VALUES // 2])
    return f"[{head}, ... ({a.size} values; min {a.min():.6g}, max {a.max():.6g})]"


def progress_line(msg: dict[str, Any], objective: str) -> str | None:
    """One line per iteration (and per failed simulation) for the terminal."""
    r = msg["row"]
    k = msg["start"]
    if msg["kind"] == "evaluation":
        if not r["failed"]:
            return None
        return (f"[start {k}] simulation failed at x = {_vec(r['x'])}: {r['message']} "
                "-> rejected (penalty), SLSQP shortens the step")
    return (f"[start {k}] it {r['iteration']:3d}  {objective} = {r['f']:.8g}  "
            f"max viol {r['max_violation']:.2e}  KKT {r['kkt']:.2e}  |du| {r['step']:.2e}  "
            f"sims {r['n_sim']}" + (f" ({r['failed']} failed)" if r["failed"] else "")
            + f"  {r['wall_time']:.2f} s")


def format_table(result: OptimizationResult, design_names: tuple[str, ...], objective: str) -> str:
    """Table of the optima found, one row per start (the best marked with *)."""
    labels = result.problem.constraint_labels
    head = (f"{'start':>5}  {objective:>14}  {'max viol':>9}  {'converged':>9}  {'feasible':>8}  "
            f"{'nit':>4}  {'sims':>5}  {'failed':>6}  x = [{', '.join(design_names)}]")
    if len(design_names) > SHOWN_VALUES:
        head = head.split("  x = [")[0] + f"  x = [{len(design_names)} design variables]"
    lines = [head]
    for o in result.starts:
        star = "*" if o.index == result.best_outcome.index else " "
        lines.append(f"{o.index:>4}{star}  {o.f:>14.8g}  {o.max_violation:>9.2e}  "
                     f"{'yes' if o.success else 'no':>9}  {'yes' if o.feasible else 'no':>8}  {o.nit:>4}  "
                     f"{o.n_sim:>5}  {o.n_failed:>6}  {_vec(o.x)}")
    if labels:
        lines.append("constraints (scaled g >= 0 is satisfied): " + "; ".join(labels))
    return "\n".join(lines)


def format_verdict(o: StartOutcome) -> str:
    """Plain sentences: did the optimizer converge, is the design feasible."""
    conv = (f"The optimizer converged ({o.message})." if o.success else
            f"The optimizer did NOT converge ({o.message}).")
    feas = ("The result is feasible" if o.feasible else "The result is NOT feasible") + \
        f" (max. scaled constraint violation {o.max_violation:.2e}, tolerance {FEAS_TOL:g})."
    return f"{conv} {feas}"


def _prepare_load_cases(case: LoadCaseSet, starts: int | None, workers: int | None, scheduler: str | None) -> None:
    """With one start, run the load cases in parallel on ``--workers``/``--scheduler`` (with
    several starts the starts run in parallel instead)."""
    if (starts or 1) == 1 and (scheduler or (workers or 1) > 1):
        from ..executor import make_executor
        case.executor = make_executor(workers, scheduler, tasks=len(case.cases))
        click.echo(f"load cases {', '.join(case.cases)} in parallel on {case.executor.description}")


@cli.command()
@case_argument
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
              help="HDF5 file for the optimization history (appended after every iteration) "
                   "[default: results/<case name>_opt.h5].")
@overwrite_option
@set_option
@click.option("-x", "--x0", "x0", multiple=True, metavar="NAME=VALUE", callback=_parse_x0,
              help="Start from this value of a design variable instead of the case's (repeatable).")
@click.option("--maxiter", type=click.IntRange(min=1), default=None,
              help="SLSQP iteration limit [default: the case's optimization.maxiter].")
@click.option("--ftol", type=FiniteFloat(0.0), default=None, metavar="FTOL",
              help="SLSQP tolerance on the scaled objective, a finite number > 0 "
                   "[default: the case's optimization.ftol].")
@click.option("--starts", type=click.IntRange(min=1), default=None,
              help="Number of starts: x0, then a Latin hypercube in the bounds [default: 1].")
@seed_option("the Latin hypercube")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes for several starts [default: min(starts, CPUs)]; with one start and "
                   "load_cases, for its load cases.")
@scheduler_option
@click.option("--resume", is_flag=True, help="Continue the unfinished starts recorded in OUTPUT.")
@click.option("--verify/--no-verify", "verify", default=None,
              help="Run the optimum again at a refined step and on a longer window and check every constraint "
                   "and member there [default: the case's optimization.verification.enabled, on].")
@click.option("--rounds", type=click.IntRange(min=0), default=None,
              help="While the verification fails, re-optimize with the failing bounds tightened by the measured "
                   "shortfall, at most this many times [default: the case's optimization.verification.rounds].")
@click.option("--plots", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Write PNG plots to DIR: history (objective, violation, KKT), design variables and "
                   "constraints against their bounds in units, recorded quantities at start and optimum "
                   "(per load case for a case with load_cases).")
@verbosity_options
def optimize(case_file: str, output: str | None, overwrite: bool, overrides: tuple[str, ...], x0: dict[str, float],
             maxiter: int | None, ftol: float | None, starts: int | None, seed: int | None,
             workers: int | None, scheduler: str | None, resume: bool, verify: bool | None, rounds: int | None,
             plots: str | None) -> None:
    """Minimize the case's objective subject to its constraints (optimization.method:
    SLSQP by default, MMA, CCSAQ or trust-constr).

    Objective, constraints and gradients come from one simulation with design sensitivities
    (direct or adjoint, as the case's sensitivity.method says) per design point.  Design
    variables are scaled to [0, 1] in their bounds; the objective is normalized by its value
    at x0.  The optimum is then verified at a refined step and on a longer window.  Exit
    status 0 when the best start converged to a feasible design that passes the
    verification, 1 otherwise.
    """
    from pathlib import Path

    from ..io.hdf5 import OutputExistsError
    from ..io.paths import check_output_path
    if resume and overwrite:
        raise OptimizationError("--resume continues OUTPUT and --overwrite replaces it: give one of them")

    def check_output(output: str) -> None:
        # name legal (also its lock file's), folder writable: before anything looks the path up
        check_output_path(output, overwrite=True)
        if not resume and Path(output).exists() and not overwrite:
            raise OutputExistsError(f"{output} exists: pass --overwrite to replace it, or --resume to continue it")
    if output is not None:
        check_output(output)                        # before the case is read
    # a case with load cases stands in for one case (its design, RESPONSE@LOADCASE responses)
    case: Any = load_any_case(case_file, overrides)
    if output is None:
        output = default_output(case, "_opt.h5")
        check_output(output)
    several = isinstance(case, LoadCaseSet)
    if several:
        _prepare_load_cases(case, starts, workers, scheduler)
    if plots:
        from ..io.paths import check_output_folder
        from ..optimize.plots import plot_files
        check_output_folder(plots, plot_files(output, plots, list(case.cases) if several else ()),
                            overwrite or resume, option="--plots")
    if case.optimization is None:
        raise OptimizationError(f"{case_file} has no 'optimization' section: add one with an objective "
                                "and constraints (see docs/case-files.md and docs/optimization.md)")
    objective = case.optimization.objective
    n_max = maxiter or case.optimization.maxiter
    bar = Progress(None, f"optimizing {case.name}")
    sims = {"it": 0, "n": 0, "total": 0, "t_sim": 0.0}

    def on_message(msg: dict[str, Any]) -> None:
        line = progress_line(msg, objective)
        if line:
            bar.close()
            click.echo(line)
        # within an iteration: simulations so far; across: iterations of at most maxiter
        if msg["kind"] == "iteration":
            sims["it"], sims["n"] = int(msg["row"]["iteration"]), 0
        else:
            sims["n"] += 1
            sims["total"] += 1
            sims["t_sim"] += float(msg["row"].get("wall_time") or 0.0)
        mean = sims["t_sim"] / max(sims["total"], 1)
        bar.update(0, f"start {msg['start']}: iteration {sims['it'] + 1} (at most {n_max}), "
                      f"{sims['n']} simulation(s) in it, {sims['total']} in all, ~{mean:.1f} s each", force=True)

    def on_done(o: StartOutcome) -> None:
        click.echo(f"[start {o.index}] finished: {'converged' if o.success else 'not converged'} "
                   f"({o.message}), {'feasible' if o.feasible else 'infeasible'}, {o.nit} iterations, "
                   f"{o.n_sim} simulations ({o.n_failed} failed)")

    def on_round(k: int, v: AnyVerification) -> None:
        bar.close()
        click.echo("")
        click.echo(f"verification of the optimum{'' if k == 0 else f' (round {k}, bounds tightened)'}:")
        click.echo(format_any_verification(v))
        if not v.passed and k < n_rounds:
            click.echo(f"round {k + 1}: re-optimizing from the optimum with the failing bounds tightened")

    n_rounds = case.optimization.verification.rounds if rounds is None else rounds
    try:
        result, verification = optimize_verified(
            case, output, verify=verify, rounds=rounds, on_round=on_round, starts=starts, seed=seed, x0=x0,
            maxiter=maxiter, ftol=ftol, workers=workers, scheduler=scheduler, resume=resume, overwrite=overwrite,
            on_message=on_message, on_start_done=on_done)
    except KeyboardInterrupt:
        bar.close()
        click.echo(f"interrupted: the history so far is in {output}; continue with --resume", err=True)
        sys.exit(130)
    finally:
        if several and case.executor is not None:
            case.executor.close()
    bar.close()
    click.echo("")
    click.echo(format_table(result, case.design_names, objective))
    b = result.best_outcome
    click.echo("")
    names = case.design_names
    shown = ", ".join(names) if len(names) <= SHOWN_VALUES else f"{len(names)} design variables"
    click.echo(f"best: start {b.index}, {objective} = {b.f:.8g}, x = {_vec(b.x)} ({shown})")
    click.echo(format_verdict(b))
    click.echo(decision_summary(output, result, case.design_units, case.response_units))
    if plots:
        for p in plot_optimization(output, plots):
            click.echo(f"plot: {p}")
    if verification is not None:
        click.echo("verified: the optimum passes the verification" if verification.passed else
                   "NOT VERIFIED: the optimum fails the verification (see above and /verification in the file)")
    click.echo(f"written: {output}")
    if not (result.converged and result.feasible) or (verification is not None and not verification.passed):
        sys.exit(1)
