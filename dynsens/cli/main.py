"""``dynsens`` command group; maps library errors to clean messages at the boundary."""
from __future__ import annotations

import os
import signal
import sys
import warnings

import click

from .. import __version__
from ..errors import DynsensError
from .options import configure_logging


class DynsensGroup(click.Group):
    """A click group that turns DynsensError into one message and exit status 2."""

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except DynsensError as exc:
            click.echo(f"Error: {exc}", err=True)
            sys.exit(2)
        except KeyboardInterrupt:
            # files being written were removed on the way out (atomic writes): say so, exit 128 + SIGINT
            click.echo("interrupted: no partial output was left", err=True)
            sys.exit(130)


class Terminated(SystemExit):
    """Raised in the main thread on SIGTERM so that atomic writes clean up; exit status 143."""


_MAIN_PID = os.getpid()


def _on_sigterm(signum: int, frame: object) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)   # a second SIGTERM ends the process at once
    if os.getpid() != _MAIN_PID:                    # a forked worker: end as by default
        os.kill(os.getpid(), signal.SIGTERM)
        return
    click.echo("terminated: no partial output was left", err=True)
    raise Terminated(128 + signal.SIGTERM)


@click.group(cls=DynsensGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dynsens")
@click.option("-v", "--verbose", count=True, help="More log output (-vv: debugging detail).")
@click.option("-q", "--quiet", is_flag=True, help="Quiet: no progress lines, no log messages below errors.")
def cli(verbose: int, quiet: bool) -> None:
    """dynsens: transient simulation with exact design gradients, and optimization."""
    configure_logging(verbose, quiet)


def main() -> None:
    """Console-script entry point."""
    from . import (check_gradients, convergence, examples, info, modes, simulate, study,  # noqa: F401  (register)
                   verify, views)
    try:
        from . import optimize  # noqa: F401
    except ImportError:  # pragma: no cover
        pass
    # plain one-line warnings for users of the console script (not for library callers)
    warnings.formatwarning = lambda msg, cat, *a, **k: f"Warning: {msg}\n"  # type: ignore[assignment]
    global _MAIN_PID
    _MAIN_PID = os.getpid()
    signal.signal(signal.SIGTERM, _on_sigterm)
    cli(prog_name="dynsens")
