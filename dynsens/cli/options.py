"""Options shared by several commands."""
from __future__ import annotations

from typing import Any, Callable

import click

case_argument = click.argument("case_file", type=click.Path(dir_okay=False, path_type=str))
set_option = click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
                          help="Override a case entry, e.g. --set integrator.dt=5e-4 "
                               "--set design.variables[0].value=3 (repeatable).")
overwrite_option = click.option("--overwrite", is_flag=True, help="Replace an existing output file.")
scheduler_option = click.option("--scheduler", default=None, metavar="ADDRESS",
                                 help="Run the simulations on this Dask distributed scheduler, e.g. "
                                      "tcp://host:8786 (pip install 'dynsens[dask]'; see the README).")


def workers_option(default: str) -> Callable:
    """``--workers N``: local worker processes (``spawn``); 1 runs in this process."""
    return click.option("--workers", type=click.IntRange(min=1), default=None,
                        help=f"Local worker processes; 1 runs in this process [default: {default}]. "
                             "Ignored with --scheduler.")


def parse_float_list(ctx: Any, param: Any, value: str | None) -> list[float] | None:
    """click callback: '1e-3,1e-4' -> [0.001, 0.0001]."""
    if value is None:
        return None
    try:
        out = [float(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(f"expected comma-separated numbers, found {value!r}") from None
    if not out or any(v <= 0 for v in out):
        raise click.BadParameter(f"expected positive numbers, found {value!r}")
    return out


def compose(*decorators: Callable) -> Callable:
    """Apply several click decorators at once."""
    def deco(fn: Callable) -> Callable:
        for d in reversed(decorators):
            fn = d(fn)
        return fn
    return deco
