"""``dynsens verify``: run a design again at a refined step and on a longer window, and check every
constraint and member there."""
from __future__ import annotations

import sys
import click
import h5py
import numpy as np

from ..case.load_cases import LoadCaseSet, load_any_case
from ..optimize.problem import OptimizationError
from ..optimize.verify import verify_design
from ..optimize.verify_cases import AnyVerification, format_any_verification, verify_load_cases
from .main import cli
from .optimize import _parse_x0
from .options import case_argument, set_option, verbosity_options


def _design_from(path: str, names: tuple[str, ...]) -> np.ndarray:
    """The best design recorded in a ``dynsens optimize`` file."""
    try:
        with h5py.File(path, "r") as f:
            best = int(f["optimization/summary"].attrs["best"])
            x = np.asarray(f[f"optimization/start_{best}"].attrs["x_opt"], dtype=float)
            stored = tuple(str(n.decode() if isinstance(n, bytes) else n) for n in f["design/names"][()])
    except (OSError, KeyError) as exc:
        raise OptimizationError(f"--from {path}: not a finished dynsens optimization file ({exc})") from None
    if stored != names:
        raise OptimizationError(f"--from {path}: its design variables ({len(stored)}) are not the case's "
                                f"({len(names)}): give the case the optimization was run on")
    return x


@cli.command()
@case_argument
@set_option
@click.option("--from", "from_file", type=click.Path(exists=True, dir_okay=False), default=None, metavar="OPT.h5",
              help="Verify the best design of this `dynsens optimize` file [default: the case's design].")
@click.option("-x", "--x0", "x0", multiple=True, metavar="NAME=VALUE", callback=_parse_x0,
              help="Set a design variable (or a whole family) to this value (repeatable).")
@click.option("--refine", type=click.IntRange(min=2), default=None,
              help="The refined run's step is dt/REFINE [default: the case's optimization.verification, 2].")
@click.option("--horizon", default=None, metavar="auto|none|T",
              help="Extend the window until the constrained peaks settle (auto), not at all (none), or to T s.")
@verbosity_options
def verify(case_file: str, overrides: tuple[str, ...], from_file: str | None, x0: dict[str, float],
           refine: int | None, horizon: str | None) -> None:
    """Check a design beyond the run that computed it.

    Runs the design as the case says, at dt/2, on a window extended until the constrained peaks
    settle, and on the window less its last tenth; prints every constraint in each run and, for
    structural models with bars, every member's largest stress and buckling ratio.  A case with
    load_cases is verified in each load case (at its own step and window), every constraint
    RESPONSE@CASE in its own load case.  Exit status 0 when every constraint and member holds in
    every run, 1 otherwise.
    """
    from ..optimize.runner import resolve_x0
    case = load_any_case(case_file, overrides)
    if case.optimization is None:
        raise OptimizationError(f"{case_file} has no 'optimization' section: the verification checks its "
                                "constraints")
    spec = case.optimization.verification
    x = resolve_x0(case, x0, base=_design_from(from_file, case.design_names) if from_file else None)
    h: float | str | None = spec.horizon
    if horizon is not None:
        h = None if horizon == "none" else "auto" if horizon == "auto" else _time(horizon)
    v: AnyVerification
    if isinstance(case, LoadCaseSet):
        v = verify_load_cases(case, x, refine=refine or spec.refine, horizon=h, tail=spec.tail)
    else:
        v = verify_design(case, x, refine=refine or spec.refine, horizon=h, tail=spec.tail)
    click.echo(format_any_verification(v))
    if not v.passed:
        sys.exit(1)


def _time(text: str) -> float:
    try:
        t = float(text)
    except ValueError:
        raise click.BadParameter(f"expected auto, none or a time in s, found {text!r}",
                                 param_hint="--horizon") from None
    if not np.isfinite(t) or t <= 0:
        raise click.BadParameter(f"expected a positive finite time, found {text!r}", param_hint="--horizon")
    return t

