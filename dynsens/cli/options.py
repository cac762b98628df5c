"""Options shared by several commands."""
from __future__ import annotations

import logging
import math
import sys
from pathlib import Path
from typing import Any, Callable

import click

from ..io.paths import safe_stem

case_argument = click.argument("case_file", type=click.Path(dir_okay=False, path_type=str))
set_option = click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
                          help="Override a case entry, e.g. --set integrator.dt=5e-4 "
                               "--set design.variables[0].value=3 (repeatable).")
overwrite_option = click.option("--overwrite", is_flag=True, help="Replace an existing output file.")
scheduler_option = click.option("--scheduler", default=None, metavar="ADDRESS",
                                 help="Run the simulations on this Dask distributed scheduler, e.g. "
                                      "tcp://host:8786 (pip install 'dynsens[dask]'; see docs/parallel.md).")


DEFAULT_OUTPUT_FOLDER = "results"


def default_output(case: Any, suffix: str) -> str:
    """The output path when ``-o`` is not given: ``results/<case name><suffix>`` relative to the
    current working directory (the case's ``name:``, which falls back to its file's stem; kept to
    letters, digits and ``. _ -``, so a name such as ``../x`` stays inside ``results/``)."""
    return str(Path(DEFAULT_OUTPUT_FOLDER) / f"{safe_stem(case.name)}{suffix}")


def workers_option(default: str) -> Callable:
    """``--workers N``: local worker processes (``spawn``); 1 runs in this process."""
    return click.option("--workers", type=click.IntRange(min=1), default=None,
                        help=f"Local worker processes; 1 runs in this process [default: {default}]. "
                             "Ignored with --scheduler.")


class FiniteFloat(click.ParamType):
    """A float option that must be finite and above ``minimum`` (click's FloatRange lets nan
    through, every comparison with it being false, and inf through an open upper end)."""

    name = "number"

    def __init__(self, minimum: float = 0.0, strict: bool = True):
        self.minimum, self.strict = minimum, strict

    @property
    def expected(self) -> str:
        """What the option takes, for help texts and messages: 'a finite number > 0'."""
        return f"a finite number {'>' if self.strict else '>='} {self.minimum:g}"

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        """The float, or a usage error naming the option, what it takes and what was given."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = math.nan
        if not (math.isfinite(v) and (v > self.minimum if self.strict else v >= self.minimum)):
            self.fail(f"expected {self.expected}, found {value!r}", param, ctx)
        return v


def parse_float_list(ctx: Any, param: Any, value: str | None) -> list[float] | None:
    """click callback: '1e-3,1e-4' -> [0.001, 0.0001]; every entry a positive finite number
    (an empty entry, as in '1e-3,,1e-4', is refused: it is a typo, not a value)."""
    if value is None:
        return None
    out = []
    for item in value.split(","):
        try:
            v = float(item)
        except ValueError:
            found = "an empty entry" if not item.strip() else repr(item.strip())
            raise click.BadParameter(f"expected comma-separated positive finite numbers, found {found} "
                                     f"in {value!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise click.BadParameter(f"expected comma-separated positive finite numbers, found "
                                     f"{item.strip()!r} in {value!r}")
        out.append(v)
    return out


def seed_option(what: str) -> Callable:
    """``--seed N``: a non-negative integer that fits the stored 64-bit attribute."""
    return click.option("--seed", type=click.IntRange(min=0, max=2 ** 63 - 1), default=None,
                        help=f"Seed of {what}, an integer >= 0 [default: random, stored].")


def compose(*decorators: Callable) -> Callable:
    """Apply several click decorators at once."""
    def deco(fn: Callable) -> Callable:
        for d in reversed(decorators):
            fn = d(fn)
        return fn
    return deco


class _StderrHandler(logging.StreamHandler):
    """Writes to the current ``sys.stderr`` (not the one at creation: tests and wrappers swap it)."""

    @property  # type: ignore[override]
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        pass


def configure_logging(verbose: int = 0, quiet: bool = False) -> None:
    """Level of the ``dynsens`` logger: WARNING, INFO with -v, DEBUG with -vv, ERROR with -q
    (which also hides the progress lines)."""
    level = logging.ERROR if quiet else max(logging.DEBUG, logging.WARNING - 10 * verbose)
    logger = logging.getLogger("dynsens")
    logger.setLevel(level)
    if not any(getattr(h, "_dynsens", False) for h in logger.handlers):
        handler = _StderrHandler()    # stderr; the results go to stdout
        handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
        handler._dynsens = True  # type: ignore[attr-defined]
        logger.addHandler(handler)
        logger.propagate = False


def _set_verbosity(ctx: click.Context, param: Any, value: Any) -> Any:
    """click callback: -v/-q given after the command name override the group's."""
    if value:
        state = ctx.meta.setdefault("dynsens_verbosity", {"verbose": 0, "quiet": False})
        state[param.name] = value
        configure_logging(state["verbose"], state["quiet"])
    return value


def verbosity_options(fn: Callable) -> Callable:
    """-v/--verbose (repeatable) and -q/--quiet on a command, through the logging module."""
    fn = click.option("-q", "--quiet", is_flag=True, expose_value=False, callback=_set_verbosity,
                      help="Quiet: no progress lines, no log messages below errors.")(fn)
    return click.option("-v", "--verbose", count=True, expose_value=False, callback=_set_verbosity,
                        help="More log output (-vv: debugging detail).")(fn)
