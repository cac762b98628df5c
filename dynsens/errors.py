"""Exception hierarchy of dynsens.

Every error a user can cause derives from `DynsensError`; the command line
turns these into one clean message and exit status, anything else is a bug and
keeps its traceback.  Each class also derives from the matching builtin so that
callers may catch either.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence


class DynsensError(Exception):
    """Root of all errors a user can cause."""


@dataclass
class Problem:
    """One problem found in a case: where (YAML path), what was found, what was expected."""

    path: str
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}" if self.path else self.message


class CaseError(DynsensError, ValueError):
    """A case file (or a ``--set`` override) is invalid.  Lists every problem at once."""

    def __init__(self, problems: Sequence[Problem] | str, source: str | None = None):
        if isinstance(problems, str):
            problems = [Problem("", problems)]
        self.problems = list(problems)
        self.source = source
        head = f"invalid case {source}" if source else "invalid case"
        lines = [f"{head} ({len(self.problems)} problem{'s' if len(self.problems) != 1 else ''}):"]
        lines += [f"  - {p}" for p in self.problems]
        super().__init__("\n".join(lines))


class ConfigurationError(DynsensError, ValueError):
    """The environment asks for something dynsens does not have (e.g. an unknown DYNSENS_KERNEL)."""


class ModelError(DynsensError, RuntimeError):
    """The model reached a state where its equations are not valid (e.g. a chamber volume <= 0)."""


class ConvergenceError(DynsensError, RuntimeError):
    """Newton-Raphson did not converge on a time step.

    Attributes carry the context a user needs: time (s), step index, iteration
    count and the residual-norm history.
    """

    def __init__(self, message: str, *, t: float, step: int, iterations: int,
                 residual_history: Sequence[float], hint: str):
        self.t = t
        self.step = step
        self.iterations = iterations
        self.residual_history = list(residual_history)
        self.hint = hint
        hist = ", ".join(f"{r:.3e}" for r in self.residual_history)
        super().__init__(
            f"{message} at t = {t:.6g} s (step {step}) after {iterations} iterations; "
            f"residual norms: [{hist}]. Try: {hint}"
        )


class StepSizeError(ConvergenceError):
    """Adaptive steps (``integrator.adaptive``) needed a step below ``dt_min``: the local error
    estimate (or Newton) still failed at the smallest step allowed.  A ConvergenceError, so
    that every caller that treats a failed run treats this one alike."""

    def __init__(self, message: str, *, t: float, step: int):
        self.t, self.step, self.iterations, self.residual_history = t, step, 0, []
        self.hint = ""
        RuntimeError.__init__(self, message)


class DesignError(ModelError):
    """A design at which an entry of the case has no finite value or breaks its range
    (e.g. a mass expression that is negative there): a failed evaluation, never a result."""


class RunSizeError(DynsensError, MemoryError):
    """A run would store more than the machine's memory allows, or take a step count beyond reason."""


class NonFiniteError(DynsensError, FloatingPointError):
    """NaN or Inf appeared in the state; says where it first appeared."""


class EventError(DynsensError, RuntimeError):
    """A response needs an event that never fired."""


@dataclass
class ProblemCollector:
    """Collects problems while a case is validated, then raises once."""

    source: str | None = None
    problems: list[Problem] = field(default_factory=list)

    def add(self, path: str, message: str) -> None:
        self.problems.append(Problem(path, message))

    def raise_if_any(self) -> None:
        if self.problems:
            raise CaseError(self.problems, self.source)
