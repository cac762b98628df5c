"""``dynsens check-gradients``: the paper's Table 1 for any case."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from ..case.load import load_case
from ..gradcheck import SCHEMES, check_gradients, to_json, to_markdown
from .main import cli
from .options import case_argument, parse_float_list, scheduler_option, set_option, workers_option


@cli.command("check-gradients")
@case_argument
@click.option("--steps", callback=parse_float_list, default="1e-3,1e-4,1e-5,1e-6", show_default=True,
              help="Relative finite-difference steps h (Δx_j = h·|x_j|).")
@click.option("--scheme", type=click.Choice(SCHEMES), default="forward", show_default=True,
              help="Finite-difference scheme of the whole simulation.")
@click.option("--rtol", type=float, default=None,
              help="Exit with status 1 unless every gradient agrees within RTOL at its best step.")
@click.option("-o", "--output", "report", type=click.Path(dir_okay=False), default=None,
              help="Report file stem: writes REPORT.md and REPORT.json.")
@workers_option("2")
@scheduler_option
@set_option
def check_gradients_cmd(case_file: str, steps: list[float], scheme: str, rtol: float | None,
                        report: str | None, workers: int | None, scheduler: str | None,
                        overrides: tuple[str, ...]) -> None:
    """Compare the semi-analytical gradient of CASE_FILE with finite differences."""
    case = load_case(case_file, overrides)
    rep = check_gradients(case, steps, scheme, workers=workers, scheduler=scheduler)
    md = to_markdown(rep)
    click.echo(md)
    if report:
        stem = Path(report)
        stem = stem.with_suffix("") if stem.suffix in (".md", ".json") else stem
        stem.parent.mkdir(parents=True, exist_ok=True)
        stem.with_suffix(".md").write_text(md, encoding="utf-8")
        stem.with_suffix(".json").write_text(json.dumps(to_json(rep), indent=2), encoding="utf-8")
        click.echo(f"written: {stem.with_suffix('.md')}, {stem.with_suffix('.json')}")
    if rtol is not None and not rep.passes(rtol):
        worst = {n: rep.best_rel_diff(n) for n in rep.responses}
        click.echo(f"gradient check FAILED at rtol = {rtol:g}: best relative differences {worst}", err=True)
        sys.exit(1)
