"""``dynsens`` command group; maps library errors to clean messages at the boundary."""
from __future__ import annotations

import logging
import sys
import warnings

import click

from .. import __version__
from ..errors import DynsensError


class DynsensGroup(click.Group):
    """A click group that turns DynsensError into one message and exit status 2."""

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except DynsensError as exc:
            click.echo(f"Error: {exc}", err=True)
            sys.exit(2)


@click.group(cls=DynsensGroup)
@click.version_option(__version__, prog_name="dynsens")
@click.option("-v", "--verbose", count=True, help="More log output.")
def cli(verbose: int) -> None:
    """dynsens: transient simulation with exact design gradients, and optimization."""
    logging.basicConfig(level=logging.WARNING - 10 * verbose, format="%(levelname)s: %(message)s")


def main() -> None:
    """Console-script entry point."""
    from . import check_gradients, convergence, simulate, study  # noqa: F401  (register commands)
    try:
        from . import optimize  # noqa: F401
    except ImportError:  # pragma: no cover
        pass
    # plain one-line warnings for users of the console script (not for library callers)
    warnings.formatwarning = lambda msg, cat, *a, **k: f"Warning: {msg}\n"  # type: ignore[assignment]
    cli()
