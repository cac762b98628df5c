"""Column colouring of the design partials: design variables whose rows of F_R are disjoint
(per-element stiffnesses, masses, bar areas) share one perturbation."""
import pickle

import numpy as np
import pytest

import dynsens
from dynsens.derivatives.partials import DesignPartials, colour_columns
from dynsens.models.base import StepState
from helpers import complex_step_gradients, rel_err
from scripts_path import duffing_chain, truss_impact

N = 6


def per_element_chain(n: int = N, t_end: float = 0.15) -> dict:
    """The Duffing chain with its own mass, stiffness and damping variable per element and a
    design load amplitude: 3n + 1 design variables, every one of them local."""
    d = duffing_chain(n, t_end)
    variables = []
    for e in d["model"]["elements"]:
        i = e["name"][1:]
        key, name, value = {"mass": ("mass", f"m_{i}", 1.0), "spring": ("k", f"k_{i}", 1.0e3),
                            "damper": ("c", f"c_{i}", 2.0)}[e["type"]]
        e[key] = name
        if e["type"] == "spring":
            e["k3"] = 1.0e6
        variables.append({"name": name, "value": value * (1.0 + 0.05 * int(i)), "lower": 0.1 * value,
                          "upper": 10.0 * value})
    d["model"]["loads"][0]["value"] = "F"
    variables.append({"name": "F", "value": 100.0, "lower": 10.0, "upper": 1000.0})
    d["design"]["variables"] = variables
    return d


def per_bar_truss(t_end: float = 0.004) -> dict:
    """The impact truss with one area per bar and a design node coordinate (Rayleigh damping on)."""
    d = truss_impact()
    d["integrator"]["t_end"] = t_end
    variables = []
    for e in d["model"]["elements"]:
        if e["type"] == "bar":
            e["area"] = f"A_{e['name']}"
            variables.append({"name": e["area"], "value": 300.0, "lower": 50.0, "upper": 2000.0})
    d["model"]["nodes"]["t2"]["coords"] = [1000.0, "h_mid"]
    variables.append({"name": "h_mid", "value": 520.0, "lower": 400.0, "upper": 600.0})
    d["design"]["variables"] = variables
    return d


def test_greedy_colouring_groups_disjoint_columns():
    rows = [np.array([0, 1]), np.array([1, 2]), np.array([2, 3]), np.array([3, 4]), np.array([], int)]
    colours = colour_columns(rows, 5)
    assert sorted(j for c in colours for j in c) == [0, 1, 2, 3, 4]
    for c in colours:                                       # pairwise disjoint within a colour
        used = np.concatenate([rows[j] for j in c])
        assert len(used) == len(set(used.tolist()))
    assert len(colours) == 2
    # no saving (every column meets every other) or no pattern: no colouring
    assert colour_columns([np.array([0, 1])] * 3, 3) is None
    assert colour_columns(None, 3) is None


def test_structural_pattern_follows_the_elements():
    case = dynsens.load_case_dict(per_element_chain())
    pattern = case.model.design_pattern()
    rows = dict(zip(case.design_names, pattern))
    assert rows["m_1"].tolist() == [0]                      # a mass: its own DOF
    assert rows["k_1"].tolist() == [0]                      # spring to ground: one free DOF
    assert rows["k_3"].tolist() == [1, 2]                   # spring u3–u2
    assert rows["c_3"].tolist() == [1, 2]
    assert rows["F"].tolist() == [N - 1]                    # the load at the tip


@pytest.mark.parametrize("partials, tol", [("forward", 1e-6), ("complex", 1e-10)])
def test_coloured_partials_match_complex_step_of_the_whole_run(partials, tol):
    case = dynsens.load_case_dict(per_element_chain(), overrides=[f"sensitivity.partials={partials}"])
    res = dynsens.run_case(case)
    m = case.x0.size
    colours = DesignPartials(case.model, case.x0, partials).colours
    # 19 variables touch 29 (row, variable) slots of 6 rows: at least ⌈29/6⌉ = 5 colours; greedy finds 5
    assert colours is not None and len(colours) == 5 and m == 3 * N + 1
    steps = res.counters["steps"] + 1
    per_step = len(colours) + (1 if partials == "forward" else 0)
    assert res.counters["sensitivity_residual_evaluations"] == per_step * steps
    ref = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, ref[name]) < tol, name


def test_coloured_and_column_by_column_partials_agree(monkeypatch):
    d = per_bar_truss()
    case = dynsens.load_case_dict(d, overrides=["sensitivity.partials=complex"])
    coloured = dynsens.run_case(case)
    assert DesignPartials(case.model, case.x0, "complex").colours is not None
    monkeypatch.setattr(type(case.model), "design_pattern", lambda self: None)
    plain = dynsens.run_case(case)
    assert coloured.counters["sensitivity_residual_evaluations"] < plain.counters["sensitivity_residual_evaluations"]
    for name, r in plain.responses.items():
        assert rel_err(coloured.responses[name].gradient, r.gradient) < 1e-12, name


def test_parameter_table_reevaluates_only_what_a_perturbation_names():
    case = dynsens.load_case_dict(per_element_chain())
    table = case.model.table
    x0 = case.x0
    full = table.evaluate(x0)
    rng = np.random.default_rng(1)
    for j in rng.choice(x0.size, 5, replace=False):
        for x in (x0 + 1e-3 * np.eye(x0.size)[j], x0 + 1e-20j * np.eye(x0.size)[j]):
            fresh = type(table).__new__(type(table))
            fresh.__dict__.update(table.__dict__, _base=None)
            assert np.array_equal(table.evaluate(x), fresh.evaluate(x))      # incremental == full
            assert not np.array_equal(table.evaluate(x), full)


def test_initial_conditions_reach_no_residual_row_but_keep_their_gradient():
    d = per_element_chain()
    d["model"]["initial"] = {"velocity": {"u3": "v0"}}
    d["design"]["variables"].append({"name": "v0", "value": 0.5, "lower": -1.0, "upper": 1.0})
    case = dynsens.load_case_dict(d, overrides=["sensitivity.partials=complex"])
    assert case.model.design_pattern()[-1].size == 0          # v0 enters only the initial state
    res = dynsens.run_case(case)
    ref = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, ref[name]) < 1e-10, name
        assert abs(r.gradient[-1]) > 0 or ref[name][-1] == 0


def test_a_perturbed_set_assembles_its_damping_only_when_its_residual_is_evaluated(monkeypatch):
    """The gradient's parameter sets: one per design variable (the outputs, the mass and the
    initial state read their element data) and one per colour (the residual's).  Only the sets
    whose residual is evaluated assemble the Rayleigh damping matrix (and its K₀): the run's own
    and one per colour, not one per variable (before: 1 + m + the colours of several variables)."""
    case = dynsens.load_case_dict(per_bar_truss())
    model = case.model
    assert model.rayleigh is not None
    assembled = []
    damping = model._damping
    monkeypatch.setattr(model, "_damping", lambda params, dtype: assembled.append(1) or damping(params, dtype))
    p = DesignPartials(model, case.x0, "forward")
    m = case.x0.size
    assert p.colours is not None and len(p.colours) < m - 1
    mass_gradient = p.of(lambda prm: np.atleast_1d(model.structural_mass(prm)))[0]
    assert assembled == []                                  # element data alone, every set
    rng = np.random.default_rng(3)
    q, qd, qdd = (rng.uniform(-1.0, 1.0, model.n) for _ in range(3))
    none = np.zeros(0)
    p.residual_partials(0.001, StepState(q, qd, qdd, none, none, none))
    assert len(assembled) == 1 + len(p.colours)             # the unperturbed set and one per colour
    # the mass is ρ A L summed: its forward-difference derivative along each area is ρ L
    bars = len(p.params0["A"])
    exact = p.params0["bar_mass"] / p.params0["A"]
    assert rel_err(mass_gradient[:bars], exact) < 1e-6


def test_a_parameter_set_pickles_with_its_matrices_assembled():
    """Sent to another process (an executor's worker), a set carries its deferred matrices."""
    case = dynsens.load_case_dict(per_bar_truss())
    params = case.model.parameters(case.x0)
    assert "D" in params and "K0" in params and not params.assembled
    copy = pickle.loads(pickle.dumps(params))
    assert type(copy) is dict and set(copy) == set(params) | {"D", "K0"}
    assert abs(copy["D"] - params["D"]).max() == 0 and params.assembled


def test_the_adjoint_does_not_stack_the_whole_batch(monkeypatch):
    """The stacked parameters of the whole batch of perturbed sets are made on first use: the adjoint of
    a case whose outputs declare their patterns (the per-bar truss) never reads them (for the
    2 252-bar ground structure they held ~450 MB), the direct mode's batched outputs do; the
    gradients agree."""
    d = per_bar_truss()
    # complex-step partials: direct and adjoint then agree to round-off
    d["sensitivity"] = {**d.get("sensitivity", {}), "method": "adjoint", "partials": "complex"}
    case = dynsens.load_case_dict(d, "truss.yaml")
    m = case.x0.size
    sizes: list[int] = []
    original = type(case.model).stack_parameters
    monkeypatch.setattr(type(case.model), "stack_parameters",
                        lambda self, sets: sizes.append(len(sets)) or original(self, sets))
    adjoint = dynsens.run_case(case, sensitivities=True, history=())
    assert adjoint.method == "adjoint" and m not in sizes, sizes        # (complex steps: m sets)
    sizes.clear()
    d["sensitivity"]["method"] = "direct"
    direct = dynsens.run_case(dynsens.load_case_dict(d, "truss.yaml"), sensitivities=True, history=())
    assert m in sizes                         # made once the direct mode's outputs ask
    for name, r in direct.responses.items():
        assert rel_err(adjoint.responses[name].gradient, r.gradient) < 1e-9
