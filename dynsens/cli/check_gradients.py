"""``dynsens check-gradients``: the paper's Table 1 for any case."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from ..case.load import load_case
from ..case.load_cases import has_load_cases, load_case_set_file
from ..derivatives.gradcheck import SCHEMES, STEP_RANGE, check_gradients, step_problem, to_json, to_markdown
from ..io.paths import atomic_write_text, check_output_path
from ..derivatives.partials_audit import audit_json, audit_markdown
from ..derivatives.partials_audit import audit_partials as audit_partials_of
from ..timeloop.progress import Progress
from .main import cli
from .options import (FiniteFloat, case_argument, overwrite_option, parse_float_list, scheduler_option,
                      set_option, verbosity_options, workers_option)

_RTOL = FiniteFloat(0.0)


@cli.command("check-gradients")
@case_argument
@click.option("--steps", callback=parse_float_list, default="1e-3,1e-4,1e-5,1e-6", show_default=True,
              help="Relative finite-difference steps h (Δx_j = h·|x_j|), comma-separated; each in "
                   f"[{STEP_RANGE['forward'][0]:g}, 1) for forward and central differences (a smaller step "
                   f"is round-off), in [{STEP_RANGE['complex'][0]:g}, 1) for complex steps.")
@click.option("--scheme", type=click.Choice(SCHEMES), default="forward", show_default=True,
              help="Finite-difference scheme of the whole simulation.")
@click.option("--rtol", type=_RTOL, default=None, metavar="RTOL",
              help=f"Exit with status 1 unless every gradient agrees within RTOL ({_RTOL.expected}) "
                   "at its best step.")
@click.option("-o", "--output", "report", type=click.Path(dir_okay=False), default=None,
              help="Report file stem: writes REPORT.md and REPORT.json.")
@workers_option("2")
@scheduler_option
@click.option("--audit-partials", is_flag=True,
              help="Also sweep the forward partials' own step (1e-2 ... 1e-12) against complex-step partials "
                   "and flag design variables without a plateau.")
@overwrite_option
@set_option
@verbosity_options
def check_gradients_cmd(case_file: str, steps: list[float], scheme: str, rtol: float | None,
                        report: str | None, workers: int | None, scheduler: str | None, audit_partials: bool,
                        overwrite: bool, overrides: tuple[str, ...]) -> None:
    """Compare the semi-analytical gradient of CASE_FILE with finite differences."""
    for h in steps:     # the accepted range depends on --scheme: checked once both are known
        why = step_problem(h, scheme)
        if why:
            raise click.BadParameter(why, param_hint="'--steps'")
    paths: list[Path] = []
    if report:
        stem = Path(report)
        stem = stem.with_suffix("") if stem.suffix in (".md", ".json") else stem
        paths = [check_output_path(stem.with_name(stem.name + ext), overwrite) for ext in (".md", ".json")]
    # a case with load cases: every load case is checked, one report section each
    if has_load_cases(case_file):
        cases = load_case_set_file(case_file, overrides).cases
    else:
        case = load_case(case_file, overrides)
        cases = {case.name: case}
    reports = {}
    for name, case in cases.items():
        with Progress(1, f"checking gradients of {name}") as bar:
            def progress(done: int, total: int) -> None:
                bar.total = total
                bar.update(done, f"simulation {done} of {total}", force=True)
            reports[name] = check_gradients(case, steps, scheme, workers=workers, scheduler=scheduler,
                                            progress=progress)
    several = len(cases) > 1
    md = "\n\n".join((f"## load case {n}\n\n" if several else "") + to_markdown(r) for n, r in reports.items())
    data: dict = {n: to_json(r) for n, r in reports.items()} if several else to_json(next(iter(reports.values())))
    if audit_partials:
        for name, case in cases.items():
            audit = audit_partials_of(case)
            md += "\n\n" + (f"## partials of load case {name}\n\n" if several else "") + audit_markdown(audit)
            (data[name] if several else data)["partials_audit"] = audit_json(audit)
    click.echo(md)
    if paths:
        atomic_write_text(paths[0], md, overwrite)
        atomic_write_text(paths[1], json.dumps(data, indent=2), overwrite)
        click.echo(f"written: {paths[0]}, {paths[1]}")
    if rtol is not None:
        _judge(reports, rtol, several)


def _judge(reports: dict, rtol: float, several: bool) -> None:
    """Exit 1 naming every gradient (and its load case) off by more than ``rtol``."""
    def at(name: str) -> str:
        return f" in load case {name}" if several else ""
    failing = [(c, n, r) for c, r in reports.items() for n in r.failing(rtol)]
    if failing:
        click.echo(f"gradient check FAILED at rtol = {rtol:g}: " + "; ".join(
            f"{n}{at(c)} (best relative difference {r.best_rel_diff(n):.2e} at h = {r.best_step(n):g})"
            for c, n, r in failing), err=True)
        sys.exit(1)
    for c, rep in reports.items():
        skipped = [n for n in rep.responses if n in rep.fixed_time or n in rep.missing]
        click.echo(f"gradient check{at(c)} passed at rtol = {rtol:g} ({len(rep.responses) - len(skipped)} "
                   "responses" + (f"; not compared: {', '.join(skipped)}" if skipped else "") + ")")
