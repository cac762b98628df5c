"""Property-based fuzz of the command line: mutated shipped cases through four commands.

Each example takes one of the shipped cases (shortened in the case to a few steps), applies one
to three random mutations to it (values of another type, negative, zero, non-finite, huge or
tiny numbers, strings in number slots, deleted or renamed keys, wrong nesting, emptied lists),
either in the file or as ``--set KEY=VALUE`` on the command line, and runs it in-process
through the click command line with ``simulate``, ``check-gradients``, ``optimize --maxiter 2``
or ``study``.  Every run falls in one class:

- ``success``: exit 0 (or 1 where the command uses it for a verdict: ``optimize`` not
  converged or not verified, ``check-gradients --rtol`` not met), every number in the written
  files and in the printed output finite;
- ``refused``: exit 2 with one ``Error:`` message and no traceback, nothing written (but for
  the record of a failed optimization: the history whose start design cannot be simulated);
- ``traceback``: an exception other than ``SystemExit`` escaped the command (a bug);
- ``nonfinite``: a success whose written HDF5 datasets or printed values hold NaN or inf
  outside the places that mark a failed design or a missing response.

The property: zero tracebacks and zero non-finite successes (and no other exit status).
The counts per class are printed in the terminal summary (``conftest.py``).

Bounded for CI: a fixed seed (``FUZZ_CLI_SEED``, default 20261128) and a fixed number of
examples (``FUZZ_CLI_EXAMPLES``, default 100), each under a 60 s alarm; a longer local campaign
raises the count, e.g. ``FUZZ_CLI_EXAMPLES=2000 FUZZ_CLI_SEED=7 pytest tests/test_cli_fuzz.py``.
Counts and times measured are in BENCHMARKS.md ("Command-line fuzz").
"""
from __future__ import annotations

import copy
import json
import math
import os
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.check_gradients  # noqa: F401  (registers the command)
import dynsens.cli.optimize  # noqa: F401  (registers the command)
import dynsens.cli.simulate  # noqa: F401  (registers the command)
import dynsens.cli.study  # noqa: F401  (registers the command)
from dynsens.cli.main import cli
from helpers import key_paths, time_limit

REPO = Path(__file__).resolve().parents[1]
SEED = int(os.environ.get("FUZZ_CLI_SEED", "20261128"))
EXAMPLES = int(os.environ.get("FUZZ_CLI_EXAMPLES", "100"))
EXAMPLE_SECONDS = 60
STEPS = 4          # time steps per run: the cases are shortened to this many in the file
MAX_STEPS = 200    # a mutation that makes more steps than this is undone

# the sdof oscillator made an optimization problem, so that `optimize` has a structural case of a
# few design variables beside the truss (the shipped optimization cases are long runs)
SDOF_OPTIMIZATION = {"objective": "q_ks", "constraints": [{"response": "q_end", "upper": 0.5}],
                     "maxiter": 5, "ftol": 1e-6}
# (shipped case, extra top-level entries): the cases that run a few steps in well under a second
BASES: dict[str, tuple[str, dict[str, Any]]] = {
    "sdof_step": ("sdof_step", {"optimization": SDOF_OPTIMIZATION}),
    "duffing_chain": ("duffing_chain", {}),
    "four_bar": ("four_bar", {}),
    "slider_crank": ("slider_crank", {}),
    "truss_lightweight": ("truss_lightweight", {}),
    "pendulum_3d": ("pendulum_3d", {}),
    "tyrolean_weir": ("tyrolean_weir", {}),
}
OPTIMIZABLE = ("sdof_step", "truss_lightweight", "tyrolean_weir")
COMMANDS = ("simulate", "check-gradients", "optimize", "study")
# what a command's exit status 1 means when it is not an error: a verdict printed in its output
VERDICT_EXIT = {"optimize": 1, "check-gradients": 1}

BAD_NUMBERS: list[Any] = [0, 0.0, -0.0, -1, -1.5, math.nan, math.inf, -math.inf, 1e308, -1e308, 1e-320,
                          10 ** 30, -(10 ** 30), 10 ** 400, 2 ** 63, True, False]
BAD_STRINGS: list[Any] = ["", " ", "abc", "1e3", "nan", "inf", "-inf", "1/0", "9**9**9", "None", "[1, 2]",
                          "ground", "u", "x" * 200, "é∞", "null"]
OTHER_TYPES: list[Any] = [None, [], {}, [1.0], [[1.0]], {"a": 1}, "text", 3, 2.5, True]


def _load_base(name: str) -> dict[str, Any]:
    shipped, extra = BASES[name]
    raw = yaml.safe_load((REPO / "cases" / f"{shipped}.yaml").read_text(encoding="utf-8"))
    raw.update(copy.deepcopy(extra))
    integ = raw["integrator"]
    integ["t_end"] = float(integ.get("t0", 0.0)) + STEPS * float(integ["dt"])
    if "optimization" in raw:       # two SLSQP iterations and one verification round at most
        raw["optimization"]["maxiter"] = 2
        raw["optimization"].setdefault("verification", {})
        if isinstance(raw["optimization"]["verification"], dict):
            raw["optimization"]["verification"]["rounds"] = 0
    return raw


# ---------------------------------------------------------------- mutations of a case mapping
def _get(raw: Any, path: tuple) -> Any:
    for k in path:
        raw = raw[k]
    return raw


def _pick(rng: np.random.Generator, seq: list[Any]) -> Any:
    return copy.deepcopy(seq[int(rng.integers(len(seq)))])


def _replacement(rng: np.random.Generator, old: Any) -> Any:
    """A value for a slot that held ``old``: a bad number, a string, another type or a scale of it."""
    kind = rng.choice(["number", "string", "type", "scale"])
    if kind == "scale" and isinstance(old, (int, float)) and not isinstance(old, bool):
        return old * float(rng.choice([-1.0, 0.0, 1e-12, 1e12, 1e300]))
    if kind == "number" or kind == "scale":
        return _pick(rng, BAD_NUMBERS)
    if kind == "string":
        return _pick(rng, BAD_STRINGS)
    return _pick(rng, OTHER_TYPES)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(rng: np.random.Generator, old: float) -> Any:
    """A number in place of the number ``old``: scaled (sign flipped, zeroed, tiny, huge) or a bad
    number outright."""
    if rng.random() < 0.6:
        return old * float(rng.choice([-1.0, 0.0, 1e-12, 1e-6, 0.5, 2.0, 1e6, 1e12, 1e300]))
    return _pick(rng, BAD_NUMBERS[:15])


def _to_set_value(value: Any) -> str:
    """The YAML text of ``value`` for ``--set KEY=VALUE`` (flow style, one line)."""
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    return yaml.safe_dump(value, default_flow_style=True, width=10 ** 6).strip().removesuffix("...").strip()


def _set_key(path: tuple) -> str:
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


def mutate(rng: np.random.Generator, raw: dict[str, Any]) -> tuple[list[str], list[str]]:
    """Mutate ``raw`` in place (one to three times); returns (descriptions, --set overrides).

    A replacement goes through ``--set`` instead of the file one time in four (the overrides'
    own parser and validation path)."""
    notes: list[str] = []
    overrides: list[str] = []
    for _ in range(int(rng.choice([1, 1, 1, 2, 2, 3]))):
        before = copy.deepcopy(raw)
        _mutate_once(rng, raw, notes, overrides)
        if _too_long(raw):      # a valid but long run (t_end x 1e6) is not what the fuzz looks for
            raw.clear()
            raw.update(before)
            notes.append("(a mutation that lengthened the run was undone)")
    return notes, overrides


def _too_long(raw: dict[str, Any]) -> bool:
    """More than MAX_STEPS fixed steps in the mutated integrator section."""
    integ = raw.get("integrator")
    if not isinstance(integ, dict):
        return False
    t0, t_end, dt = integ.get("t0", 0.0), integ.get("t_end"), integ.get("dt")
    if not all(_is_number(v) for v in (t0, t_end, dt)):
        return False
    try:
        return bool(dt > 0 and (t_end - t0) / dt > MAX_STEPS)
    except (OverflowError, ZeroDivisionError):
        return True


def _mutate_once(rng: np.random.Generator, raw: dict[str, Any], notes: list[str], overrides: list[str]) -> None:
    """One mutation of ``raw`` in place (see :func:`mutate`)."""
    paths = [p for p in key_paths(raw) if p]
    numeric = [p for p in paths if _is_number(_get(raw, p))]
    # half of the mutations change a number (a case that still loads, a run that meets it);
    # the others change the case's shape
    if numeric and rng.random() < 0.5:
        path, op = numeric[int(rng.integers(len(numeric)))], "number"
    else:
        path = paths[int(rng.integers(len(paths)))]
        op = str(rng.choice(["replace", "replace", "delete", "rename", "nest", "empty"]))
    parent, key = _get(raw, path[:-1]), path[-1]
    old = parent[key]
    if op in ("replace", "number"):
        new = _number(rng, old) if op == "number" else _replacement(rng, old)
        if rng.random() < 0.25:
            trial = copy.deepcopy(raw)
            _get(trial, path[:-1])[key] = new
            if _too_long(trial):
                return
            overrides.append(f"{_set_key(path)}={_to_set_value(new)}")
            notes.append(f"--set {overrides[-1]}")
            return
        parent[key] = new
        notes.append(f"{_set_key(path)}: {old!r:.60} -> {new!r:.60}")
    elif op == "delete":
        del parent[key]
        notes.append(f"{_set_key(path)}: deleted")
    elif op == "rename" and isinstance(parent, dict):
        new_key = str(rng.choice([f"{key}s", str(key).upper(), f"{key}_", str(key)[:-1] or "x", "value"]))
        if new_key in parent:
            return
        parent[new_key] = parent.pop(key)
        notes.append(f"{_set_key(path)}: renamed to {new_key!r}")
    elif op == "nest":
        parent[key] = [old] if rng.random() < 0.5 else {str(key): old}
        notes.append(f"{_set_key(path)}: nested one level deeper")
    elif op == "empty":
        parent[key] = [] if isinstance(old, list) or rng.random() < 0.5 else {}
        notes.append(f"{_set_key(path)}: emptied")


# ---------------------------------------------------------------- running and classifying
@dataclass
class Outcome:
    """One fuzz example: what ran and how it ended."""

    case: str
    command: str
    mutations: list[str]
    kind: str = ""
    detail: str = ""
    seconds: float = 0.0
    files: list[str] = field(default_factory=list)


# per command, option sets drawn with equal chance besides the case (each run stays a few simulations)
OPTION_SETS: dict[str, list[list[str]]] = {
    "simulate": [[], ["--no-sensitivities"]],
    "check-gradients": [["--steps", "1e-4"], ["--steps", "1e-3", "--scheme", "central"],
                        ["--steps", "1e-4", "--rtol", "1e-2"]],
    "optimize": [["--maxiter", "2", "--rounds", "0"],
                 ["--maxiter", "2", "--no-verify", "--starts", "2", "--seed", "3"]],
    "study": [["--sample", "lhs:2", "--seed", "1"], ["--sample", "sobol:2", "--seed", "2", "--gradients"]],
}
OUTPUT_NAMES = {"simulate": "run.h5", "check-gradients": "grad", "optimize": "opt.h5", "study": "study.h5"}


def _command_args(command: str, case_file: Path, out: Path, options: list[str], overrides: list[str]) -> list[str]:
    """The command line of one run: every command in this process (``--workers 1``)."""
    workers = [] if command == "simulate" else ["--workers", "1"]
    return [command, str(case_file), "-o", str(out / OUTPUT_NAMES[command]), *options, *workers,
            *[a for o in overrides for a in ("--set", o)]]


NONFINITE_TEXT = re.compile(r"(?<![\w.])[-+]?(nan|inf(?:inity)?)(?![\w])", re.IGNORECASE)


def _failed_rows(obj: Any) -> Any:
    """The rows of a table (a study's rows, an optimization's evaluations) whose NaN is a marker,
    or None: failed designs (their boolean ``failed`` column is set) and, in a study, designs
    with a missing response (their ``message`` says which: "NAME missing (why)")."""
    flag = obj.parent.get("failed")
    if not (isinstance(flag, h5py.Dataset) and flag.dtype.kind == "b" and flag.shape[:1] == obj.shape[:1]):
        return None
    marked = np.asarray(flag[()], dtype=bool)
    message = obj.parent.get("message")
    if isinstance(message, h5py.Dataset) and message.shape[:1] == obj.shape[:1]:
        texts = [m.decode() if isinstance(m, bytes) else str(m) for m in message[()]]
        marked |= np.array([" missing (" in t for t in texts], dtype=bool)
    return marked


def _no_bound(name: str, data: Any) -> bool:
    """A lower bound of -inf or an upper bound of +inf: the value of an absent bound."""
    leaf = name.rsplit("/", 1)[-1]
    a = np.asarray(data, dtype=float) if np.asarray(data).dtype.kind == "f" else np.asarray([np.nan])
    if leaf == "lower":
        return bool(np.all(np.isfinite(a) | (a == -np.inf)))
    if leaf == "upper":
        return bool(np.all(np.isfinite(a) | (a == np.inf)))
    return False


def nonfinite_datasets(path: Path) -> list[str]:
    """Datasets and attributes of an HDF5 file with a NaN or inf where a finite number belongs.

    NaN is the file's marker in two places, allowed there: the rows of failed designs (a study's
    rows, an optimization's evaluations: their ``failed`` flag is set) or of designs with a missing
    response (the row's message names it), and a response marked ``missing``."""
    bad: list[str] = []
    with h5py.File(path, "r") as f:
        def visit(name: str, obj: Any) -> None:
            for k, v in obj.attrs.items():
                a = np.asarray(v)
                if a.dtype.kind in "fc" and not np.isfinite(a).all() and not obj.attrs.get("missing") \
                        and not _no_bound(k, a):
                    bad.append(f"{name} attribute {k}: {v!r}")
            if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in "fc":
                return
            data = np.asarray(obj[()])
            finite = np.isfinite(data)
            if finite.all() or obj.parent.attrs.get("missing") or _no_bound(name, data):
                return
            failed = _failed_rows(obj) if data.ndim else None
            if failed is not None and finite[~failed].all():
                return
            bad.append(f"{name}: {int((~finite).sum())} of {data.size} not finite")

        visit("/", f)
        f.visititems(visit)
    return bad


# an absent bound printed as an interval: [-inf, upper] or [lower, inf]
NO_BOUND_TEXT = re.compile(r"\[\s*-inf\s*,|,\s*\+?inf\s*\]", re.IGNORECASE)


def nonfinite_printed(text: str) -> list[str]:
    """Lines of a command's output that print a NaN or inf value, except the lines that report a
    failed simulation (whose message may name the NaN that stopped it) and an absent bound
    (-inf below, inf above)."""
    return [line for line in text.splitlines()
            if NONFINITE_TEXT.search(NO_BOUND_TEXT.sub(",", line))
            and "FAILED" not in line and "simulation failed" not in line]


def _status(path: Path) -> str:
    with h5py.File(path, "r") as f:
        return str(f.attrs.get("status", ""))


def classify(command: str, result: Any, out: Path) -> tuple[str, str]:
    """(class, detail) of one finished run: see the module docstring."""
    exc = result.exception
    if exc is not None and not isinstance(exc, SystemExit):
        import traceback
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)[-6:])
        return "traceback", f"{exc!r}\n{tb}"
    text = result.output
    if "Traceback (most recent call last)" in text:
        return "traceback", text[-2000:]
    code = result.exit_code
    written = sorted(p for p in out.rglob("*") if p.is_file())
    if code == 2:
        err = result.stderr
        n_errors = sum(line.startswith("Error:") for line in err.splitlines())
        if n_errors != 1:
            return "unclear", f"exit 2 with {n_errors} 'Error:' messages:\n{err[-1500:]}"
        # a file left behind must be a record of the failure: optimize keeps the history of a start
        # design that cannot be simulated, with status "failed" (test_optimize.py)
        leftover = [p.name for p in written if not (p.suffix == ".h5" and _status(p) == "failed")]
        if leftover:
            return "unclear", f"refused but wrote {leftover}:\n{err[-800:]}"
        return "refused", err.strip().splitlines()[-1][:300]
    if code == 0 or code == VERDICT_EXIT.get(command):
        bad = [f"{p.name}: {b}" for p in written if p.suffix == ".h5" for b in nonfinite_datasets(p)]
        printed = nonfinite_printed(result.stdout)
        for p in written:
            if p.suffix in (".md", ".json"):
                printed += nonfinite_printed(p.read_text(encoding="utf-8"))
        if bad or printed:
            return "nonfinite", "\n".join(bad + printed)[:3000]
        return "success", f"exit {code}"
    return "unclear", f"exit {code}:\n{result.output[-1500:]}"


def run_example(index: int, rng: np.random.Generator, folder: Path) -> Outcome:
    """Draw one mutated case and command, run it through the command line and classify it."""
    command = str(rng.choice(COMMANDS))
    # optimize needs an optimization section: drawn among the cases that have one
    names = [n for n in BASES if command != "optimize" or n in OPTIMIZABLE]
    name = str(rng.choice(names))
    raw = _load_base(name)
    options = OPTION_SETS[command][int(rng.integers(len(OPTION_SETS[command])))]
    notes, overrides = mutate(rng, raw)
    out = folder / f"ex{index:04d}"
    out.mkdir()
    case_file = folder / f"ex{index:04d}.yaml"
    case_file.write_text(yaml.safe_dump(raw, sort_keys=False, allow_unicode=True), encoding="utf-8")
    outcome = Outcome(name, command, [" ".join(options)] + notes)
    args = _command_args(command, case_file, out, options, overrides)
    t0 = time.perf_counter()
    with warnings.catch_warnings(), time_limit(EXAMPLE_SECONDS):
        warnings.simplefilter("ignore")
        result = CliRunner().invoke(cli, args, catch_exceptions=True)
    outcome.seconds = time.perf_counter() - t0
    outcome.kind, outcome.detail = classify(command, result, out)
    return outcome


FUZZ_COUNTS: dict[str, Any] = {}


@pytest.fixture(scope="module")
def warm() -> None:
    """Run every base case once per command, unmutated: compilation stays out of the examples,
    and an unmutated case must succeed (else the fuzz would only test refusals)."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        for name in BASES:
            for command in ("simulate",):
                out = Path(tmp) / f"{name}_{command}"
                out.mkdir()
                case_file = Path(tmp) / f"{name}.yaml"
                case_file.write_text(yaml.safe_dump(_load_base(name), sort_keys=False), encoding="utf-8")
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result = CliRunner().invoke(cli, _command_args(command, case_file, out, [], []))
                kind, detail = classify(command, result, out)
                assert kind == "success", f"unmutated {name} with {command}: {kind}\n{detail}"


def test_mutated_cases_through_the_command_line(warm: None, tmp_path: Path, record_property: Any) -> None:
    rng = np.random.default_rng(SEED)
    outcomes: list[Outcome] = []
    t0 = time.perf_counter()
    for i in range(EXAMPLES):
        outcomes.append(run_example(i, rng, tmp_path))
    wall = time.perf_counter() - t0
    counts = {k: sum(o.kind == k for o in outcomes) for k in ("success", "refused", "traceback", "nonfinite",
                                                               "unclear")}
    per_command = {c: {k: sum(o.kind == k and o.command == c for o in outcomes) for k in counts if
                       any(o.kind == k and o.command == c for o in outcomes)} for c in COMMANDS}
    summary = {"seed": SEED, "examples": EXAMPLES, "wall_s": round(wall, 1), "counts": counts,
               "per_command": per_command}
    FUZZ_COUNTS.update(summary)
    record_property("cli_fuzz", json.dumps(summary))
    print(f"\ncommand-line fuzz: {json.dumps(summary)}")
    bad = [o for o in outcomes if o.kind in ("traceback", "nonfinite", "unclear")]
    report = "\n\n".join(f"[{o.kind}] {o.command} {o.case} with {o.mutations}:\n{o.detail}" for o in bad)
    assert not bad, f"{len(bad)} of {EXAMPLES} runs failed the property ({counts}):\n\n{report}"


# ---------------------------------------------------------------- what the fuzz found, kept as regressions
def _refused_cleanly(args: list[str], out: Path, *fragments: str) -> None:
    """Exit 2, one 'Error:' line naming every fragment, no traceback, nothing written."""
    result = CliRunner().invoke(cli, args, catch_exceptions=True)
    kind, detail = classify(args[0], result, out)
    assert kind == "refused", f"{kind}: {detail}"
    for f in fragments:
        assert f in result.stderr, f"{f!r} not in {result.stderr}"


HUGE_INT = "1" + "0" * 400      # YAML reads it as an exact int that no float holds


@pytest.mark.parametrize("key,expected", [
    ("design.variables[0].value", "expected a finite number"),    # was an OverflowError
    ("model.loads[0].value", "expected a finite number"),         # was an OverflowError
    ("responses[1].rho", "expected a positive number"),           # was a TypeError from np.isfinite
])
def test_integers_beyond_the_float_range_are_refused(tmp_path: Path, key: str, expected: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    args = _command_args("simulate", REPO / "cases" / "sdof_step.yaml", out, [],
                         [f"{key}={HUGE_INT}", "integrator.t_end=0.004"])
    _refused_cleanly(args, out, key, expected, "an integer of 401 digits")


def test_a_ks_response_without_rho_is_refused(tmp_path: Path) -> None:
    """Was a KeyError('rho') after the missing key had been reported."""
    raw = _load_base("sdof_step")
    del raw["responses"][1]["rho"]
    case_file = tmp_path / "case.yaml"
    case_file.write_text(yaml.safe_dump(raw, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    _refused_cleanly(_command_args("simulate", case_file, out, [], []), out, "responses[1].rho", "missing required key")


@pytest.mark.parametrize("value", [10 ** 30, 10 ** 400], ids=["1e30", "1e400"])
def test_a_stabilization_beyond_int64_is_a_clean_outcome(tmp_path: Path, value: int) -> None:
    """model.stabilization.alpha = 10^30 or 10^400 (ints that np.isfinite cannot take) was a TypeError.
    10^30 is a finite number, accepted (this run then stops cleanly: its matrix is singular);
    10^400 holds no float and is refused at its key."""
    out = tmp_path / "out"
    out.mkdir()
    args = _command_args("simulate", REPO / "cases" / "tyrolean_weir.yaml", out, [],
                         [f"model.stabilization.alpha={value}", "integrator.t_end=0.004"])
    if value > 1e308:
        _refused_cleanly(args, out, "model.stabilization.alpha", "expected a finite number >= 0")
    else:
        kind, detail = classify("simulate", CliRunner().invoke(cli, args), out)
        assert kind in ("success", "refused"), f"{kind}: {detail}"


def test_an_empty_dof_list_in_a_quantity_is_refused(tmp_path: Path) -> None:
    """quantity: {dof: []} loaded and then failed in the run with an IndexError."""
    out = tmp_path / "out"
    out.mkdir()
    args = _command_args("simulate", REPO / "cases" / "sdof_step.yaml", out, [],
                         ["responses[1].quantity.dof=[]", "integrator.t_end=0.004"])
    _refused_cleanly(args, out, "responses[1].quantities[0].dof", "non-empty list of dof names, found []")


def test_check_gradients_reports_missing_responses_without_nan(tmp_path: Path) -> None:
    """A response missing in a short run (an event not reached) was printed and written as
    [nan, nan]; the JSON report held NaN, which is not JSON.  Now 'missing' and null."""
    raw = _load_base("pendulum_3d")
    case_file = tmp_path / "case.yaml"
    case_file.write_text(yaml.safe_dump(raw, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    result = CliRunner().invoke(cli, _command_args("check-gradients", case_file, out, ["--steps", "1e-4"], []))
    kind, detail = classify("check-gradients", result, out)
    assert kind == "success", f"{kind}: {detail}"
    assert "| missing |" in result.stdout and "is missing:" in result.stdout

    def no_constants(c: str) -> None:
        raise AssertionError(f"{c} in the JSON report")
    data = json.loads((out / "grad.json").read_text(encoding="utf-8"), parse_constant=no_constants)
    assert data["missing"] and all(data["values"][n] is None for n in data["missing"])
