"""Property-based fuzzing of the case loader (hypothesis).

Inputs are mutations of the shipped cases: keys dropped or duplicated, values replaced by
wrong types, extreme and non-finite numbers and hostile expressions, list entries repeated,
and the text re-encoded (UTF-16, Latin-1, NUL bytes, byte-order marks).  The property: every
input either loads or is refused with a DynsensError (never another exception, never a
hang), and a case that loads runs a few steps to either a DynsensError or a result whose
every response value and gradient is finite.

Bounded for CI: a fixed number of examples per test (FUZZ_EXAMPLES, default 200) and a
deadline per example; the README's reliability section records the count and the time.
"""
from __future__ import annotations

import copy
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from dynsens.case.load import load_case, load_case_text  # noqa: E402
from dynsens.errors import DynsensError  # noqa: E402
from dynsens.simulation import run_case  # noqa: E402
from helpers import key_paths, time_limit  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# the fast cases (structural and multibody), so that a loaded case can also be run briefly
CASE_NAMES = ("sdof_step", "duffing_chain", "pendulum_3d", "four_bar", "slider_crank", "truss_impact")
TEXTS = {n: (REPO / "cases" / f"{n}.yaml").read_text(encoding="utf-8") for n in CASE_NAMES}
RAWS = {n: yaml.safe_load(t) for n, t in TEXTS.items()}
EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "200"))
# no per-example deadline from hypothesis (the first run of a model type compiles kernels);
# a hang is caught by the alarm of _time_limit instead
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])

HOSTILE = ["1/0", "9**9**9", "(-8)**(1/3)", "log(-1)", "sqrt(-1)", "__import__('os')", "1e308*10",
           "nan", "inf", "-inf", "m.real", "lambda: 0", "[1, 2]", "1 if 1 else 0", "(" * 300 + "1" + ")" * 300,
           "sin(" * 120 + "1" + ")" * 120, "+".join(["1"] * 999), "x" * 3000, "pi", "e", "exp(1000)",
           "abs(-0.0)", "0*0", "1e-320", "'text'", "a=1", "", " ", "∞", "\x00", "2**-2000", "1" * 400,
           "sin(1, 2)", "atan2(1)", "min()", "sqrt(0)", "0**-1", "(-1)**0.5", "1e308+1e308"]
NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                    st.sampled_from([0, -0.0, 1e-308, 5e-324, 1e308, -1e308, 2**63, -1]))
LEAVES = st.one_of(NUMBERS, st.sampled_from(HOSTILE), st.text(max_size=20), st.booleans(), st.none(),
                   st.lists(NUMBERS, max_size=4), st.dictionaries(st.text(max_size=5), NUMBERS, max_size=2))


def _parent(raw: Any, path: tuple) -> Any:
    node = raw
    for k in path[:-1]:
        node = node[k]
    return node


@st.composite
def mutated_case(draw: Any) -> tuple[str, Any]:
    name = draw(st.sampled_from(CASE_NAMES))
    raw = copy.deepcopy(RAWS[name])
    for _ in range(draw(st.integers(1, 3))):
        paths = key_paths(raw)
        if not paths:
            break
        path = paths[draw(st.integers(0, len(paths) - 1))]
        parent, key = _parent(raw, path), path[-1]
        op = draw(st.sampled_from(["drop", "replace", "replace", "repeat"]))
        if op == "drop":
            del parent[key]
        elif op == "replace":
            parent[key] = draw(LEAVES)
        elif isinstance(parent, list):
            parent.append(copy.deepcopy(parent[key]))
        else:
            parent[key] = [copy.deepcopy(parent[key])] * 2
    return name, raw


def _finite(result: Any) -> bool:
    for r in result.responses.values():
        if r.missing:
            continue
        if not np.all(np.isfinite(r.value)):
            return False
        if r.gradient is not None and not np.all(np.isfinite(r.gradient)):
            return False
    return True


def _run_briefly(case: Any) -> None:
    """A few steps of the loaded case: a DynsensError or a finite result."""
    plan = case.plan
    t_end = min(plan.t_end, plan.t0 + 5 * plan.dt)
    from dataclasses import replace
    case.plan = replace(plan, t_end=t_end)
    try:
        res = run_case(case, history=())
    except DynsensError:
        return
    assert _finite(res), {n: (r.value, r.gradient) for n, r in res.responses.items()}


EXAMPLE_SECONDS = 60


@pytest.fixture(scope="module", autouse=True)
def _compiled() -> None:
    """Run every base case once so that kernel compilation is not inside an example."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in CASE_NAMES:
            _run_briefly(load_case_text(TEXTS[name], f"{name}.yaml"))


def _load_or_refuse(load: Any) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return load()
        except DynsensError as exc:
            assert str(exc).strip(), "an error needs a message"
            return None


@FUZZ
@given(mutated_case())
def test_mutated_mappings_load_or_are_refused(tmp_path_factory: Any, case: tuple[str, Any]) -> None:
    name, raw = case
    try:
        text = yaml.safe_dump(raw, sort_keys=False, allow_unicode=True)
    except yaml.YAMLError:
        return
    with time_limit(EXAMPLE_SECONDS):
        loaded = _load_or_refuse(lambda: load_case_text(text, f"{name}.yaml"))
        if loaded is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                _run_briefly(loaded)


@st.composite
def mutated_text(draw: Any) -> bytes:
    name = draw(st.sampled_from(CASE_NAMES))
    lines = TEXTS[name].splitlines(keepends=True)
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["duplicate", "drop", "alias", "indent", "garbage"]))
        if op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "drop" and len(lines) > 1:
            del lines[i]
        elif op == "alias":
            lines.insert(i, "x0: &x0 [1, 1, 1, 1, 1, 1, 1, 1]\n"
                         + "".join(f"x{k}: &x{k} [{', '.join([f'*x{k - 1}'] * 8)}]\n" for k in range(1, 8)))
        elif op == "indent":
            lines[i] = "  " + lines[i]
        else:
            lines.insert(i, draw(st.text(max_size=30)) + "\n")
    text = "".join(lines)
    enc = draw(st.sampled_from(["utf-8", "utf-8", "utf-8-sig", "utf-16", "utf-32", "latin-1", "nul"]))
    if enc == "nul":
        return text.encode("utf-8") + b"\x00"
    return text.encode(enc, errors="replace")


@FUZZ
@given(mutated_text())
def test_mutated_texts_load_or_are_refused(tmp_path_factory: Any, data: bytes) -> None:
    path = tmp_path_factory.mktemp("fuzz") / "case.yaml"
    path.write_bytes(data)
    with time_limit(EXAMPLE_SECONDS):
        _load_or_refuse(lambda: load_case(path))
