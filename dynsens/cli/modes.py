"""``dynsens modes``: natural frequencies (and linear buckling factors) of a structural case, with
their design gradients."""
from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from ..analysis.modes import Buckling, Modes, buckling, modes
from ..case.load import Case, load_case
from .main import cli
from .optimize import _parse_x0
from .options import case_argument, overwrite_option, set_option, verbosity_options

SHOWN_VARIABLES = 6     # gradient columns printed (all are written to the file)


def _table(names: tuple[str, ...], rows: list[tuple[str, float, np.ndarray | None, bool]], unit: str) -> str:
    shown = names[:SHOWN_VARIABLES]
    head = f"{'mode':>4}  {unit:>14}" + "".join(f"  {'d/d' + n:>14}" for n in shown)
    if len(names) > SHOWN_VARIABLES:
        head += f"  (+{len(names) - SHOWN_VARIABLES} more in the file)"
    lines = [head]
    for label, value, grad, repeated in rows:
        cells = "".join(f"  {g:>14.6g}" for g in grad[:SHOWN_VARIABLES]) if grad is not None else ""
        lines.append(f"{label:>4}  {value:>14.8g}{cells}" + ("  (repeated: directional)" if repeated else ""))
    return "\n".join(lines)


def format_modes(m: Modes, names: tuple[str, ...]) -> str:
    """The frequencies and their gradients as a table."""
    rows = [(str(i + 1), float(f), None if m.gradient is None else m.gradient[i], bool(m.repeated[i]))
            for i, f in enumerate(m.frequencies)]
    return f"natural frequencies at t = {m.time:g} s:\n" + _table(names, rows, "f [Hz]")


def format_buckling(b: Buckling, names: tuple[str, ...]) -> str:
    """The load factors and their gradients as a table."""
    rows = [(str(i + 1), float(v), None if b.gradient is None else b.gradient[i], bool(b.repeated[i]))
            for i, v in enumerate(b.factors)]
    return f"linear buckling load factors of the load at t = {b.load_time:g} s:\n" + _table(names, rows, "factor")


def _write(path: Path, overwrite: bool, case: Case, x: np.ndarray, m: Modes, b: Buckling | None) -> None:
    """The file: the common header and ``/design``, then ``/modes`` and ``/buckling``."""
    import h5py

    from ..io.hdf5 import atomic_h5, write_design, write_header
    text = h5py.string_dtype()
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, "completed", "modes" + (" and buckling" if b else ""))
        write_design(f, case.design_names, x, case.lower, case.upper)
        g = f.create_group("modes")
        g.attrs["time"] = m.time
        g.create_dataset("frequencies", data=m.frequencies)
        g.create_dataset("shapes", data=m.shapes)
        g.create_dataset("repeated", data=m.repeated)
        g.create_dataset("dof_labels", data=np.array(m.dof_labels, dtype=object), dtype=text)
        if m.gradient is not None:
            g.create_dataset("gradient", data=m.gradient)
        if b is not None:
            h = f.create_group("buckling")
            h.attrs["load_time"] = b.load_time
            h.create_dataset("factors", data=b.factors)
            h.create_dataset("shapes", data=b.shapes)
            h.create_dataset("repeated", data=b.repeated)
            if b.gradient is not None:
                h.create_dataset("gradient", data=b.gradient)


@cli.command("modes")
@case_argument
@set_option
@click.option("-x", "--x0", "x0", multiple=True, metavar="NAME=VALUE", callback=_parse_x0,
              help="Set a design variable (or a whole family) to this value (repeatable).")
@click.option("--count", type=click.IntRange(min=1), default=6, show_default=True, help="Number of modes.")
@click.option("--time", "time", type=float, default=None, metavar="T",
              help="Linearize at the state the run reaches at T s [default: the initial state].")
@click.option("--buckling", "with_buckling", is_flag=True,
              help="Also the linear buckling load factors of the case's load (at its largest, or --load-time).")
@click.option("--load-time", type=float, default=None, metavar="T", help="The load of time T is the reference load.")
@click.option("--no-sensitivities", is_flag=True, help="Skip the design gradients.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None, help="Write an HDF5 file.")
@overwrite_option
@verbosity_options
def modes_command(case_file: str, overrides: tuple[str, ...], x0: dict[str, float], count: int, time: float | None,
                  with_buckling: bool, load_time: float | None, no_sensitivities: bool, output: str | None,
                  overwrite: bool) -> None:
    """Natural frequencies and mode shapes of a structural case, and their design gradients.

    The model is linearized at rest at the initial state (or at the state of --time) and
    K φ = ω² M φ solved; gradients dλ/dx = φᵀ(dK/dx − λ dM/dx)φ.  With --buckling, the load
    factors λ of (K₀ + λ K_G)φ = 0 for the case's load.
    """
    from ..io.paths import check_output_path
    from ..optimize.runner import resolve_x0
    if output:
        check_output_path(output, overwrite=overwrite)
    case = load_case(case_file, overrides)
    x = resolve_x0(case, x0)
    m = modes(case, x, count=count, time=time, sensitivities=not no_sensitivities)
    click.echo(format_modes(m, case.design_names))
    b = None
    if with_buckling:
        b = buckling(case, x, count=min(count, 3), load_time=load_time, sensitivities=not no_sensitivities)
        click.echo(format_buckling(b, case.design_names))
    if output:
        _write(Path(output), overwrite, case, x, m, b)
        click.echo(f"written: {output}")
