"""``dynsens study``: a case evaluated at many designs, rows appended to HDF5 as they finish."""
from __future__ import annotations

import sys
from typing import Any

import click
import numpy as np

from ..case.load import load_case
from ..io.paths import check_output_folder, check_output_path
from ..study import format_summary, plot_study, read_study, run_study
from ..study.plots import study_plot_files
from .main import cli
from .options import (case_argument, default_output, overwrite_option, scheduler_option, seed_option, set_option,
                      workers_option)


@cli.command()
@case_argument
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
              help="HDF5 file of the study (a row appended as each design finishes) "
                   "[default: results/<case name>_study.h5].")
@click.option("--sample", default=None, metavar="SPEC",
              help="lhs:N (Latin hypercube), sobol:N (N = 2^k), grid:AxBx... (points per variable) in the "
                   "case's bounds, or a CSV file with a header of design-variable names. Required unless --resume.")
@click.option("--gradients", is_flag=True, help="Also compute the design gradients (the case's sensitivity method).")
@seed_option("lhs/sobol")
@workers_option("the number of CPUs")
@scheduler_option
@click.option("--resume", is_flag=True, help="Compute only the designs without a row in OUTPUT.")
@overwrite_option
@set_option
@click.option("--plots", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Write study_responses.png, study_sensitivity.png and study_pairs.png to DIR.")
def study(case_file: str, output: str | None, sample: str | None, gradients: bool, seed: int | None,
          workers: int | None, scheduler: str | None, resume: bool, overwrite: bool,
          overrides: tuple[str, ...], plots: str | None) -> None:
    """Evaluate CASE_FILE at every design of --sample; failed designs are recorded, not fatal.

    Rows are on disk as soon as each design finishes: after a kill, --resume computes
    only the designs without a row.  Read the table with dynsens.read_study(OUTPUT).
    """
    if output is not None:      # before the case is read (run_study checks it again, and locks it)
        check_output_path(output, overwrite=True)
    case = load_case(case_file, overrides)
    names = case.design_names
    if output is None:
        output = default_output(case, "_study.h5")
        check_output_path(output, overwrite=True)
    if plots:       # before the run, not after it
        check_output_folder(plots, study_plot_files(plots), overwrite or resume, option="--plots")

    def on_row(row: dict[str, Any], done: int, total: int) -> None:
        x = ", ".join(f"{n}={v:.6g}" for n, v in zip(names, row["x"]))
        what = f"FAILED: {row['message']}" if row["failed"] else (
            f"{row['wall_time']:.2f} s" + (f" ({row['message']})" if row["message"] else ""))
        click.echo(f"[{done}/{total}] design {row['index']}: {x}: {what}")

    try:
        table = run_study(case, output, sample, gradients=gradients, seed=seed, workers=workers,
                          scheduler=scheduler, resume=resume, overwrite=overwrite, on_row=on_row)
    except KeyboardInterrupt:
        click.echo(f"interrupted: the finished designs are in {output}; continue with --resume", err=True)
        sys.exit(130)
    n_failed = int(table.failed.sum())
    click.echo("")
    click.echo(f"{len(table.index)} designs ({table.sample}{'' if table.seed is None else f', seed {table.seed}'}), "
               f"{n_failed} failed, total simulation time {np.sum(table.wall_time):.1f} s")
    if len(table.index) - n_failed >= 3:
        click.echo(format_summary(table))
    if plots:
        for p in plot_study(read_study(output), plots):
            click.echo(f"plot: {p}")
    click.echo(f"written: {output}")
