"""``dynsens convergence``: error against time step and wall time for each gradient method."""
from __future__ import annotations

import click

from ..case.load import load_case
from ..analysis.convergence import (METHODS, extrapolated, format_order, observed_order, reference_note, report_files,
                                    work_precision, write_report)
from ..io.paths import check_output_folder
from ..timeloop.progress import Progress
from .main import cli
from .options import (DEFAULT_OUTPUT_FOLDER, case_argument, overwrite_option, parse_float_list, scheduler_option,
                      set_option, verbosity_options, workers_option)

DEFAULT_FOLDER = f"{DEFAULT_OUTPUT_FOLDER}/convergence"


@cli.command("convergence")
@case_argument
@click.option("--dt", "dts", callback=parse_float_list, default=None,
              help="Comma-separated time steps (default: the case's Δt × 4, 2, 1, 1/2, 1/4).")
@click.option("--methods", default=",".join(METHODS), show_default=True,
              help=f"Comma-separated subset of {', '.join(METHODS)}.")
@click.option("-o", "--output", "outdir", type=click.Path(file_okay=False), default=DEFAULT_FOLDER,
              show_default=True,
              help="Folder for the tables and plots (their names start with the case's name).")
@workers_option("1: the wall times are part of the study")
@scheduler_option
@overwrite_option
@set_option
@verbosity_options
def convergence_cmd(case_file: str, dts: list[float] | None, methods: str, outdir: str,
                    workers: int | None, scheduler: str | None, overwrite: bool,
                    overrides: tuple[str, ...]) -> None:
    """Work-precision study of CASE_FILE: tables (markdown, CSV) and log-log plots."""
    check_output_folder(outdir, [], overwrite)
    case = load_case(case_file, overrides)
    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    bad = [m for m in chosen if m not in METHODS]
    if bad:
        raise click.BadParameter(f"unknown methods {bad} (known: {', '.join(METHODS)})", param_hint="--methods")
    check_output_folder(outdir, report_files(case, outdir), overwrite)
    dts = dts or [case.plan.dt * f for f in (4, 2, 1, 0.5, 0.25)]
    span = case.plan.t_end - case.plan.t0
    too_long = [dt for dt in dts if dt > span]
    if too_long:        # checked before any run, as integrator.dt is
        raise click.BadParameter(f"expected steps of at most t_end - t0 = {span:g} s (a run of at least one full "
                                 f"step), found {', '.join(f'{dt:g}' for dt in too_long)}", param_hint="--dt")
    if len(set(dts)) < 2:
        raise click.BadParameter(f"expected at least two different steps (the reference is extrapolated from "
                                 f"the two finest, and an order needs two), found {', '.join(map(str, dts))}",
                                 param_hint="--dt")
    with Progress(1, f"convergence of {case.name}") as bar:
        def progress(done: float, total: float, note: str) -> None:
            bar.total = total
            bar.update(done, note, force=True)
        rows, _, _ = work_precision(case, dts, chosen, workers=workers, scheduler=scheduler, progress=progress)
    files = write_report(case, rows, outdir, overwrite=overwrite)
    if not extrapolated(dts):
        click.echo(f"warning: {reference_note(dts)}", err=True)
    for n in rows[0].values:
        click.echo(f"{n}: observed order {format_order(observed_order(rows, n, chosen[0]))} "
                   f"(scheme order {case.scheme.order})")
    click.echo("written: " + ", ".join(str(f) for f in files))
