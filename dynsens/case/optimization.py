"""The ``optimization`` section of a case (objective, constraints, optimizer settings).

Validated at load time together with the rest of the case.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import ProblemCollector
from ..case_keys import allowed
from ..models._keys import check_keys, did_you_mean
from .responses_spec import read_number

METHODS = ("SLSQP", "MMA", "CCSAQ", "trust-constr", "IPOPT")   # dynsens.optimize.methods serves them


@dataclass(frozen=True)
class ConstraintSpec:
    """A response bounded as lower <= response <= upper (either bound may be absent)."""

    response: str
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class VerificationSpec:
    """``optimization.verification``: the run of the optimum at a refined step and on a longer
    window (:mod:`dynsens.optimize.verify`).  ``horizon`` is ``"auto"``, None or an end time (s)."""

    enabled: bool = True
    refine: int = 2
    horizon: float | str | None = "auto"
    tail: float = 0.1
    rounds: int = 0
    safety: float = 1.5


@dataclass(frozen=True)
class OptimizationSpec:
    """Objective (minimized), constraints and optimizer settings."""

    objective: str
    constraints: tuple[ConstraintSpec, ...] = ()
    method: str = "SLSQP"
    maxiter: int = 100
    ftol: float = 1e-6
    options: dict[str, Any] = field(default_factory=dict)
    verification: VerificationSpec = field(default_factory=VerificationSpec)


def validate_optimization(spec: Any, response_names: tuple[str, ...],
                          pc: ProblemCollector) -> OptimizationSpec | None:
    """Check the ``optimization`` mapping against the case's responses; None if absent or invalid."""
    if spec is None:
        return None
    if not check_keys(spec, "optimization", allowed("optimization"), pc,
                      required=("objective",)):
        return None
    n0 = len(pc.problems)
    obj = spec.get("objective")
    if obj not in response_names:
        pc.add("optimization.objective", f"unknown response {obj!r}{did_you_mean(obj, response_names)} "
                                         f"(responses: {', '.join(response_names)})")
    cons = []
    for i, c in enumerate(spec.get("constraints", []) or []):
        p = f"optimization.constraints[{i}]"
        if not check_keys(c, p, allowed("optimization.constraint"), pc, required=("response",)):
            continue
        name = c.get("response")
        if name not in response_names:
            pc.add(f"{p}.response", f"unknown response {name!r}{did_you_mean(name, response_names)}")
        # a bound is finite (nan would hold for no value): no bound is a key left out
        lo, up = (read_number(c[k], f"{p}.{k}", pc) if c.get(k) is not None else None for k in ("lower", "upper"))
        if c.get("lower") is None and c.get("upper") is None:
            pc.add(p, "give 'upper' (response <= upper) and/or 'lower'")
        elif lo is not None and up is not None and lo > up:
            pc.add(p, f"lower > upper ({lo} > {up}): did you swap the bounds?")
        cons.append(ConstraintSpec(str(name), lo, up))
    method = spec.get("method", "SLSQP")
    if method not in METHODS:
        pc.add("optimization.method", f"expected one of {', '.join(METHODS)}, found {method!r}")
    maxiter = spec.get("maxiter", 100)
    if not isinstance(maxiter, int) or isinstance(maxiter, bool) or maxiter < 1:
        pc.add("optimization.maxiter", f"expected a positive integer, found {maxiter!r}")
    ftol = read_number(spec.get("ftol", 1e-6), "optimization.ftol", pc, positive=True)
    verification = _verification(spec.get("verification"), pc)
    if len(pc.problems) > n0:
        return None
    return OptimizationSpec(str(obj), tuple(cons), method, maxiter, float(ftol or 0.0),   # None: returned above
                            verification=verification)


def _integer(spec: dict, key: str, default: int, least: int, pc: ProblemCollector) -> int:
    v = spec.get(key, default)
    if not isinstance(v, int) or isinstance(v, bool) or v < least:
        pc.add(f"optimization.verification.{key}", f"expected an integer >= {least}, found {v!r}")
        return default
    return v


def _verification(spec: Any, pc: ProblemCollector) -> VerificationSpec:
    """``optimization.verification`` (defaults where absent)."""
    if spec is None:
        return VerificationSpec()
    p = "optimization.verification"
    if not check_keys(spec, p, allowed(p), pc):
        return VerificationSpec()
    enabled = spec.get("enabled", True)
    if not isinstance(enabled, bool):
        pc.add(f"{p}.enabled", f"expected true or false, found {enabled!r}")
    refine = _integer(spec, "refine", 2, 2, pc)
    rounds = _integer(spec, "rounds", 0, 0, pc)
    horizon: float | str | None = spec.get("horizon", "auto")
    if horizon in ("none", None):
        horizon = None
    elif horizon != "auto":
        horizon = read_number(horizon, f"{p}.horizon", pc, positive=True)
    tail = read_number(spec.get("tail", 0.1), f"{p}.tail", pc)
    if tail is not None and not 0.0 <= tail < 1.0:
        pc.add(f"{p}.tail", f"expected a share of the window in [0, 1), found {tail!r}")
    safety = read_number(spec.get("safety", 1.5), f"{p}.safety", pc)
    if safety is not None and not safety >= 1.0:
        pc.add(f"{p}.safety", f"expected a factor >= 1, found {safety!r}")
    return VerificationSpec(bool(enabled), refine, horizon, float(tail or 0.0), rounds, float(safety or 1.5))
