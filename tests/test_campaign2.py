"""The second hostile campaign (issue 37): one test per defect class, each failing before its fix.

Bad input gets one clear error naming the key path, what was expected and what was found;
never a traceback or a silently wrong result.
"""
from __future__ import annotations

import codecs
import copy

import numpy as np
import pytest
from click.testing import CliRunner

import dynsens
import dynsens.cli.convergence  # noqa: F401  (registers the commands)
import dynsens.cli.optimize  # noqa: F401
import dynsens.cli.simulate  # noqa: F401
import dynsens.cli.study  # noqa: F401
from dynsens import CaseError
from dynsens.case.load import load_case, load_case_dict
from dynsens.cli.main import cli
from dynsens.errors import DesignError
from test_beams import cantilever, portal_frame


def invoke(*args: object) -> object:
    """The command line in-process; a crash shows as exit status 1 with its exception kept."""
    return CliRunner().invoke(cli, [str(a) for a in args])


def _problems(raw: dict) -> list[tuple[str, str]]:
    with pytest.raises(CaseError) as err:
        load_case_dict(copy.deepcopy(raw))
    return [(p.path, p.message) for p in err.value.problems]


@pytest.mark.parametrize("section, dim", [
    ({"shape": "tube", "D": 60.0, "t": 31.0}, 2),
    ({"shape": "box", "b": 20.0, "h": 50.0, "t": 10.5}, 2),
    ({"shape": "box", "b": 80.0, "h": 20.0, "t": 10.5}, 2),
    ({"shape": "tube", "D": 60.0, "t": 31.0}, 3),
    ({"shape": "box", "b": 20.0, "h": 50.0, "t": 10.5}, 3),
])
def test_sections_that_cannot_exist(section: dict, dim: int) -> None:
    raw = cantilever(2, section=section)
    if dim == 3:
        raw["model"]["dim"] = 3
        for el in raw["model"]["elements"]:
            el["G"] = 80000.0
        raw["model"]["nodes"] = {n: {"coords": v["coords"] + [0.0], **({"fixed": "all"} if "fixed" in v else {})}
                                 for n, v in raw["model"]["nodes"].items()}
    found = _problems(raw)
    msgs = [m for p, m in found if p == "model.elements[0].section.t"]
    assert msgs and "expected a wall t <=" in msgs[0] and f"found t = {section['t']:g}" in msgs[0], found
    # a solid section (walls that just meet) exists
    solid = dict(section, t=min(v for k, v in section.items() if k in ("D", "b", "h")) / 2)
    ok = copy.deepcopy(raw)
    for el in ok["model"]["elements"]:
        el["section"] = dict(solid)
    load_case_dict(ok)


def test_sections_that_cannot_exist_during_optimization() -> None:
    """A design the optimizer reaches where a tube's wall passes its radius is a failed evaluation."""
    case = load_case_dict(portal_frame())
    x = case.x0.copy()
    x[case.design_names.index("D")] = 9.0                     # t = 5 > D/2
    with pytest.raises(DesignError, match=r"model\.elements\[0\]\.section\.t: expected a wall t <= D/2"):
        dynsens.run_case(case, x)


def _yaml(path: str) -> dict:
    import yaml
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


@pytest.mark.parametrize("kind, dofs, needle", [
    ("spring", ["ground"], "ground"),
    ("damper", ["ground"], "ground"),
    ("spring", ["u", "u"], "one DOF"),
    ("damper", ["ground", "ground"], "ground"),
])
def test_degenerate_elements(kind: str, dofs: list, needle: str) -> None:
    from helpers import SDOF_DESIGN
    raw = copy.deepcopy(SDOF_DESIGN)
    value = {"k": 5.0} if kind == "spring" else {"c": 1.0}
    raw["model"]["elements"].append({"type": kind, "name": "extra", "dofs": dofs, **value})
    found = _problems(raw)
    assert [m for p, m in found if p == "model.elements[3].dofs" and needle in m], found


def test_zero_length_bars_and_beams_are_refused_at_load_and_at_a_design() -> None:
    """A bar or beam whose end nodes coincide has no direction: it gave raw numpy warnings and a
    NaN/Inf error without the element's key path."""
    raw = _yaml("cases/two_bar_shape.yaml")                    # tip at (0, -H), H = 1800 at the start
    raw["model"]["nodes"]["right"] = {"coords": [0.0, -1800.0]}
    found = _problems(raw)
    assert [m for p, m in found if p == "model.elements[1].nodes" and "zero length" in m
            and "[0.0, -1800.0]" in m], found
    raw["model"]["nodes"]["right"] = {"coords": [0.0, -1500.0]}   # valid at the start, not at H = 1500
    case = load_case_dict(raw)
    x = case.x0.copy()
    x[case.design_names.index("H")] = 1500.0
    with pytest.raises(DesignError, match=r"model\.elements\[1\]\.nodes: expected two distinct end points"):
        dynsens.run_case(case, x)
    frame = cantilever(2)
    frame["model"]["nodes"]["n2"]["coords"] = list(frame["model"]["nodes"]["n1"]["coords"])
    assert [m for p, m in _problems(frame) if p == "model.elements[1].nodes" and "a beam of zero length" in m]


def test_degenerate_inertia_tensor_is_refused() -> None:
    raw = _yaml("cases/pendulum_3d.yaml")
    bodies = raw["model"]["bodies"]
    name = next(n for n, b in bodies.items() if isinstance(b, dict) and "inertia" in b)
    bodies[name]["inertia"] = [1.0, 1.0, 1.0, 2.0, 0.0, 0.0]     # eigenvalues -1, 1, 3
    found = _problems(raw)
    msgs = [m for p, m in found if p == f"model.bodies.{name}.inertia"]
    assert msgs and "positive definite inertia tensor" in msgs[0] and "-1" in msgs[0], found
    bodies[name]["inertia"] = [1.0, 1.0, 1.0, 0.5, 0.0, 0.0]     # a valid tensor with a product
    load_case_dict(raw)


@pytest.mark.parametrize("budget", [".inf", "1e400", "1e400 GiB", str(10 ** 400)])
def test_inputs_that_overflow_memory_budget(budget: str) -> None:
    import yaml
    from helpers import SDOF_DESIGN
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["sensitivity"]["memory_budget"] = yaml.safe_load(budget)
    found = _problems(raw)
    assert [m for p, m in found if p == "sensitivity.memory_budget" and "expected a positive size" in m], found


def test_memory_budget_limit_is_stated_exactly() -> None:
    """Just above the limit: the message named "at most 5e+18" (rounded up from 2**62 ≈ 4.61e18)."""
    from helpers import SDOF_DESIGN
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["sensitivity"]["memory_budget"] = 4999999999999999999
    found = _problems(raw)
    assert [m for p, m in found if p == "sensitivity.memory_budget" and "at most 2**62 = 4611686018427387904" in m]
    raw["sensitivity"]["memory_budget"] = 2 ** 62
    load_case_dict(raw)


@pytest.mark.parametrize("spec", ["lhs:100000000000", "sobol:1099511627776", "grid:100000", "grid:4000x4000x4000"])
def test_inputs_that_overflow_study_samples(tmp_path, spec: str) -> None:
    from test_study import SDOF
    r = invoke("study", SDOF, "-o", tmp_path / "s.h5", "--sample", spec)
    assert r.exit_code == 2 and "at most 10,000,000 designs" in r.output and "Traceback" not in r.output, r.output
    assert not (tmp_path / "s.h5").exists()


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-8-sig"])
def test_csv_not_utf8_read_by_its_byte_order_mark(tmp_path, encoding: str) -> None:
    from dynsens.study import sample_designs
    from test_study import SDOF
    csv = tmp_path / "d.csv"
    text = "k,m\n60,1.5\n80,2.0\n"
    csv.write_bytes((codecs.BOM_UTF16_BE + text.encode(encoding)) if encoding == "utf-16-be" else text.encode(encoding))
    case = load_case(SDOF)
    x = sample_designs(case, str(csv), None)
    np.testing.assert_array_equal(x[:, [case.design_names.index("k"), case.design_names.index("m")]],
                                  [[60, 1.5], [80, 2.0]])


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be"])
def test_csv_utf16_without_byte_order_mark_is_named(tmp_path, encoding: str) -> None:
    """It decoded as UTF-8 and was refused for "unknown design variable(s) 'm\\x00'"."""
    from test_study import SDOF
    csv = tmp_path / "d.csv"
    csv.write_bytes("k,m\n60,1.5\n".encode(encoding))
    r = invoke("study", SDOF, "-o", tmp_path / "s.h5", "--sample", csv)
    assert r.exit_code == 2 and "found NUL bytes" in r.output and "UTF-16 without a byte-order mark" in r.output
    assert not (tmp_path / "s.h5").exists()


@pytest.mark.parametrize("encoding", ["latin-1", "cp1252"])
def test_csv_not_utf8(tmp_path, encoding: str) -> None:
    from test_study import SDOF
    csv = tmp_path / "d.csv"
    csv.write_bytes("k,m\n60,1.5\n80,2.0\n# Müller\n".encode(encoding))
    r = invoke("study", SDOF, "-o", tmp_path / "s.h5", "--sample", csv)
    assert r.exit_code == 2 and "expected a UTF-8 text file" in r.output and str(csv) in r.output, r.output
    assert not (tmp_path / "s.h5").exists()


@pytest.fixture
def sdof_files(tmp_path):
    """The SDOF design case (short) as a file; returns (case path, folder)."""
    import yaml
    from helpers import SDOF_DESIGN
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["integrator"]["t_end"] = 0.3
    path = tmp_path / "sdof.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path, tmp_path


def _refused(r, *needles: str) -> None:
    assert r.exit_code == 2 and "Traceback" not in r.output, r.output
    for n in needles:
        assert n in r.output, r.output


UNMAKEABLE = "/proc/dynsens_plots"          # the file system refuses a folder here, also for root


def test_plots_folder_checked_before_the_run(sdof_files) -> None:
    case, d = sdof_files
    for cmd in (["simulate", case, "-o", d / "r.h5"], ["optimize", case, "-o", d / "r.h5", "--maxiter", "1"],
                ["study", case, "-o", d / "r.h5", "--sample", "lhs:2"]):
        _refused(invoke(*cmd, "--plots", UNMAKEABLE), "--plots", "/proc")
        assert not (d / "r.h5").exists()


@pytest.mark.parametrize("command, existing", [("simulate", "r.png"), ("study", "study_responses.png"),
                                               ("optimize", "r_design.png")])
def test_plots_not_overwritten_without_overwrite(sdof_files, command: str, existing: str) -> None:
    case, d = sdof_files
    (d / "plots").mkdir()
    (d / "plots" / existing).write_bytes(b"mine")
    extra = {"simulate": [], "study": ["--sample", "lhs:2"], "optimize": ["--maxiter", "1"]}[command]
    _refused(invoke(command, case, "-o", d / "r.h5", *extra, "--plots", d / "plots"), existing, "--overwrite")
    assert (d / "plots" / existing).read_bytes() == b"mine" and not (d / "r.h5").exists()


@pytest.mark.parametrize("output, needle", [
    ("r" * 250 + ".h5", "expected a file name of at most"),
    ("d" * 300 + "/r.h5", "expected folder and file names of at most 255 bytes"),
    ("/".join(["d" * 200] * 25) + "/r.h5", "(the file system's limit)"),
])
def test_tracebacks_output_path_too_long(sdof_files, output: str, needle: str) -> None:
    case, d = sdof_files
    _refused(invoke("simulate", case, "-o", d / output), needle)


def test_tracebacks_optimize_plots_unwritable(sdof_files) -> None:
    case, d = sdof_files
    # for root, permission bits allow /proc: the file system's own refusal is what is reported
    _refused(invoke("optimize", case, "-o", d / "o.h5", "--maxiter", "1", "--plots", UNMAKEABLE),
             "--plots: expected a folder", "/proc")
    assert not (d / "o.h5").exists()


def test_tracebacks_resume_with_garbage_tail(sdof_files) -> None:
    case, d = sdof_files
    out = d / "o.h5"
    assert invoke("optimize", case, "-o", out, "--maxiter", "2").exit_code in (0, 1)
    data = bytearray(out.read_bytes())
    data[-30000:] = np.random.default_rng(7).bytes(30000)
    out.write_bytes(bytes(data))
    _refused(invoke("optimize", case, "-o", out, "--maxiter", "3", "--resume"), "o.h5 is damaged",
             "without --resume")
    assert out.read_bytes() == bytes(data)


@pytest.mark.parametrize("kwargs, needle", [
    ({"history": "q"}, "history: expected a sequence of names"),
    ({"history": ["q", "velocity"]}, "found unknown 'velocity'"),
    ({"sensitivities": "no"}, "sensitivities: expected True, False or None"),
])
def test_python_api_validates_simulate_arguments(kwargs: dict, needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        dynsens.simulate("cases/sdof_step.yaml", **kwargs)
    # the valid spellings run
    sim = dynsens.simulate("cases/sdof_step.yaml", history=["q"], sensitivities=False, **{"integrator.t_end": 0.1})
    assert set(sim.history) == {"q"} and all(np.isnan(g).all() for g in sim.gradients.values())


def test_python_api_validates_nan_tolerance() -> None:
    from helpers import SDOF_DESIGN
    with pytest.raises(ValueError, match="ftol: expected a finite number > 0, found nan"):
        dynsens.optimize(SDOF_DESIGN, ftol=float("nan"))
    report = dynsens.check_gradients("cases/sdof_step.yaml", steps=[1e-6], **{"integrator.t_end": 0.1})
    with pytest.raises(ValueError, match="rtol: expected a finite number > 0"):
        report.passes(float("nan"))


@pytest.mark.parametrize("call, needle", [
    (lambda c: dynsens.check_gradients(c, "1e-4"), "steps: expected a sequence of finite numbers > 0, found '1e-4'"),
    (lambda c: dynsens.check_gradients(c, [1e-4, -1e-5]), "steps: expected a sequence of finite numbers > 0"),
    (lambda c: dynsens.optimize(c, maxiter=float("nan")), "maxiter: expected a whole number >= 1 or None, found nan"),
    (lambda c: dynsens.optimize(c, starts=0), "starts: expected a whole number >= 1"),
    (lambda c: dynsens.optimize(c, x0={"k": float("nan")}), "x0: expected a finite start value for each design "
                                                            "variable, found {'k': nan}"),
])
def test_python_api_names_the_bad_argument(call, needle: str) -> None:
    """These raised numpy's TypeError, "cannot convert float NaN to integer", or called NaN
    "outside the bounds" in the command line's words (-x); nothing runs before the check."""
    from helpers import SDOF_DESIGN
    with pytest.raises(ValueError) as err:
        call(copy.deepcopy(SDOF_DESIGN))
    assert needle in str(err.value)


@pytest.mark.parametrize("name", ["pi", "e", "sqrt"])
def test_family_named_like_an_expression_constant(name: str) -> None:
    from test_families import per_member
    raw = per_member(name=name, assign={"area": name, "inertia": f"{name}**2*10/(8*pi)"})
    found = _problems(raw)
    msgs = [m for p, m in found if p == "design.families[0].name"]
    assert msgs and "not a constant or function of the expressions" in msgs[0], found


@pytest.mark.parametrize("dts, needle", [("1", "expected steps of at most t_end - t0 = 0.5 s"),
                                         ("0.02,1", "found 1"),
                                         ("0.01", "expected at least two different steps")])
def test_convergence_dt_checked_before_the_run(tmp_path, dts: str, needle: str) -> None:
    from test_study import SDOF
    r = invoke("convergence", SDOF, "--set", "integrator.t_end=0.5", "--dt", dts, "--methods", "ddm-forward",
               "-o", tmp_path / "out")
    assert r.exit_code == 2 and needle in r.output and "--dt" in r.output, r.output
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_convergence_case_name_stays_inside_output(tmp_path) -> None:
    import yaml
    from test_study import SDOF
    raw = yaml.safe_load(SDOF.read_text())
    raw["name"] = "../../escaped/x"
    case = tmp_path / "a" / "b" / "c.yaml"
    case.parent.mkdir(parents=True)
    case.write_text(yaml.safe_dump(raw))
    r = invoke("convergence", case, "--set", "integrator.t_end=0.2", "--dt", "0.02,0.01", "--methods", "ddm-forward",
               "-o", tmp_path / "a" / "b" / "out")
    assert r.exit_code == 0, r.output
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert all(p.parts[:3] == ("a", "b", "out") for p in written if p.name != "c.yaml"), written


def test_messages_beam_buckling_refused_once_at_the_response_type() -> None:
    """A buckling ratio over a frame's beams and a bar without 'inertia': beams have a buckling
    ratio now (issue 33), so the one problem left is the bar's, once, at the response's
    'elements' key (a path that exists), naming the bar."""
    raw = portal_frame()
    raw["responses"].append({"name": "buckle", "type": "buckling_ratio", "rho": 20.0})
    found = _problems(raw)
    at = len(raw["responses"]) - 1
    mine = [(p, m) for p, m in found if p.startswith(f"responses[{at}]")]
    assert len(mine) == 1, found
    path, msg = mine[0]
    assert path == f"responses[{at}].elements", found
    assert "inertia" in msg and "brace" in msg, msg
    assert not any(b in msg for b in ("col_a", "col_b", "girder_1", "girder_2")), msg
    raw["responses"][at]["elements"] = ["col_a", "col_b", "girder_1", "girder_2"]
    load_case_dict(copy.deepcopy(raw))          # the beams alone: accepted


def test_messages_ks_components_take_the_short_label() -> None:
    raw = _yaml("cases/duffing_chain.yaml")
    quantity = {"dof": [f"u{i}" for i in range(1, 21)], "kind": "displacement"}
    raw["responses"].append({"name": "u10_ks", "type": "ks", "quantity": quantity, "components": ["u10"],
                             "rho": 200.0})
    raw["responses"].append({"name": "u10_end", "type": "value", "quantity": quantity, "component": "u10"})
    case = load_case_dict(raw)
    res = dynsens.run_case(case, sensitivities=False)
    assert res.responses["u10_ks"].value >= res.responses["u10_end"].value - 1e-12
    raw["responses"][-2]["components"] = ["u99"]
    assert [m for p, m in _problems(raw) if p == f"responses[{len(raw['responses']) - 2}].components"
            and "'u99' not found" in m]


def test_messages_an_ambiguous_short_label_is_not_called_missing() -> None:
    """`displacement` is the last part of both labels: it was refused as "not found"."""
    raw = _yaml("cases/duffing_chain.yaml")
    two = {"dof": ["u19", "u20"], "kind": "displacement"}
    raw["responses"][0] = {"name": "tip_end", "type": "value", "quantity": two, "component": "displacement"}
    raw["output"] = {"quantities": [{"name": "two", "quantity": two, "component": "displacement"}]}
    raw["responses"][1].update(quantity=two, components=["displacement"])     # a KS over the pair
    found = dict(_problems(raw))
    for path in ("responses[0].component", "output.quantities[0].component", "responses[1].components"):
        assert "component 'displacement' is ambiguous: it names 2 components (u19.displacement, " \
               "u20.displacement)" in found[path], found
    raw["responses"][0]["component"] = "u20"          # a short label that names one component
    raw["output"]["quantities"][0]["component"] = "u20.displacement"
    raw["responses"][1]["components"] = ["u19", "u20"]
    load_case_dict(raw)


def test_messages_dimensionless_unit_prints_bare() -> None:
    from dynsens.optimize.summary import _u
    assert _u("-") == "" and _u("MPa") == " MPa" and _u("") == ""


def test_messages_monitor_labels_and_optimize_help() -> None:
    from dynsens.cli.simulate import monitor_label
    assert monitor_label("constraint_position") == "constraint position drift"
    assert monitor_label("sensitivity_constraint_position") == "sensitivity constraint position residual"
    assert "drift" not in monitor_label("sensitivity_constraint_scale")
    r = invoke("optimize", "-h")
    assert "adjoint" in " ".join(r.output.split()), r.output


def test_docstrings_cite_tests_that_exist() -> None:
    """Every tests/test_*.py (and test function named after it) a dynsens docstring or comment
    cites exists."""
    import re
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    cite = re.compile(r"tests/(test_\w+\.py)(?:,\s*(test_\w+)|::(test_\w+))?")
    missing = []
    for src in sorted((root / "dynsens").rglob("*.py")):
        for m in cite.finditer(src.read_text(encoding="utf-8")):
            test_file = root / "tests" / m.group(1)
            function = m.group(2) or m.group(3)
            if not test_file.exists():
                missing.append(f"{src.relative_to(root)}: {m.group(0)}")
            elif function and f"def {function}(" not in test_file.read_text(encoding="utf-8"):
                missing.append(f"{src.relative_to(root)}: {m.group(0)} (no such test)")
    assert not missing, missing
