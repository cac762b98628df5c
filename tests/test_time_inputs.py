"""Time functions settle, and a mechanism's time inputs are kept once they have: the kept inputs
are those evaluated afresh, bit for bit, before, across and after the settling time."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.models.multibody.kernel import kernel_params
from dynsens.models.multibody.residual import time_inputs, time_inputs_steps
from dynsens.models.timefunctions import TimeFunction

F64 = np.float64
# (kind, parameter values, table times, the settling time T that settled_from must give)
SETTLING = [
    ("constant", [], (), -np.inf),
    ("step", [0.3], (), 0.3),
    ("ramp", [0.1, 0.4], (), 0.4),
    ("smoothstep", [0.0, 0.02], (), 0.02),
    ("ramp", [0.4, 0.1], (), 0.4),            # end before start (a design expression may do so)
    ("pulse", [0.2, 0.05], (), 0.25),
    ("table", [1.0, 3.0, -2.0], (0.0, 0.5, 0.9), 0.9),
    ("harmonic", [2.0, 0.1], (), np.inf),
]


@pytest.mark.parametrize("kind, values, table_t, T", SETTLING)
def test_a_time_function_no_longer_changes_after_it_settled(kind, values, table_t, T) -> None:
    fn = TimeFunction(kind, tuple(range(len(values))), table_t)
    for pv in (np.array(values, float), np.array([values, np.array(values) * 1.01]),       # batched
               np.array(values, complex) + 1e-20j):                                          # complex step
        assert fn.settled_from(pv) == T
        if not np.isfinite(T):
            continue
        after = [np.asarray(fn.value(t, pv)) for t in (T + 1e-12, T + 0.01, T + 3.0, 1e6)]
        assert all(np.array_equal(a, after[0]) for a in after), kind
        if kind != "table":                        # (the table's last segment ends at its value)
            assert not np.array_equal(np.asarray(fn.value(T - 1e-3, pv)), after[0]), \
                f"{kind}: settles no earlier than {T}"
    if kind == "harmonic":
        pv = np.array(values, float)
        assert fn.value(10.0, pv) != fn.value(10.3, pv)


def _weir(pump_function: dict | None = None):
    raw = yaml.safe_load((CASES / "tyrolean_weir.yaml").read_text())
    if pump_function is not None:
        for el in raw["model"]["forces"]:
            if el.get("type") == "hydraulic_cylinder":
                el["pump_function"] = pump_function
    case = dynsens.load_case_dict(raw, "weir")
    model = case.model
    x = case.x0
    sets = [model.parameters(x), model.parameters(x * (1 + 1e-3)), model.parameters(x * (1 - 2e-3))]
    return model, kernel_params(model.layout, sets[0]), model.stack_parameters(sets)


def _fresh(model, kp, t: float) -> tuple:
    return time_inputs_steps(model, kp, np.array([t]), F64)


@pytest.mark.parametrize("pump", [None, {"type": "harmonic", "frequency": 3.0}])
def test_kept_time_inputs_are_those_evaluated_afresh(pump) -> None:
    model, kp1, kp3 = _weir(pump)
    settles = pump is None                     # the weir's pump: smoothstep over 0.02 s
    for kp in (kp1, kp3):
        kept = []
        for t in (0.0, 0.01, 0.0199, 0.02, 0.0201, 0.5, 0.5, 3.0, 7.25):
            got = time_inputs(model, kp, t, F64)
            for a, b in zip(got, _fresh(model, kp, t)):
                assert a.shape == b.shape and np.array_equal(a, b), t
            kept.append(got)
        if settles:                            # past 0.02 s the same arrays serve
            assert kept[5][0] is kept[7][0] is kept[8][0]
            assert kept[4][0] is not kept[2][0]
        else:
            assert not np.array_equal(kept[7][0], kept[8][0])
        assert kept[5][0] is kept[6][0]        # one step's iterates: one evaluation


@pytest.mark.parametrize("ts", [np.linspace(0.03, 0.5, 7), np.linspace(0.0, 0.05, 9), np.array([0.01])])
def test_a_block_of_times_takes_one_set_of_inputs_once_settled(ts) -> None:
    model, _, kp = _weir()
    ext, f_ext, g = time_inputs_steps(model, kp, ts, F64)
    B = kp.B
    settled = bool(np.all(ts > 0.02))
    assert ext.shape[0] == (B if settled else B * len(ts))
    for k, t in enumerate(ts):
        one = _fresh(model, kp, t)
        rows = np.arange(k * B, (k + 1) * B) % ext.shape[0]     # the kernel repeats entries cyclically
        assert np.array_equal(ext[rows], one[0])
        assert np.array_equal(f_ext[rows % f_ext.shape[0]], one[1][np.arange(B) % one[1].shape[0]])
        assert np.array_equal(g, one[2])


def test_a_structural_models_kept_loads_are_those_evaluated_afresh() -> None:
    """A structural model keeps f_ext of each parameter set and reuses it at another time once both
    times are past every load's settling time: bit for bit what a fresh evaluation gives, before,
    inside and after a pulse, for the run's parameters and a stacked (perturbed) set in turn."""
    import scripts_path  # noqa: F401  (puts scripts/ on the path)
    from make_cases import duffing_chain
    d = duffing_chain(6, t_end=0.3)
    d["model"]["loads"].append({"dof": "u2", "value": 5.0, "function": {"type": "step", "t0": 0.05}})
    model = dynsens.load_case_dict(d, "chain.yaml").model
    x = np.array([1.0, 0.5, 1.0e3, 1.0e5])
    params = model.parameters(x)
    stacked = model.stack_parameters([model.parameters(x * 1.001), model.parameters(x * 0.999)])
    times = [0.0, 0.02, 0.05, 0.07, 0.1, 0.1 + 1e-12, 0.13, 0.2, 0.2, 0.29]
    for t in times:
        for prm in (params, stacked):
            kept = model.external_force(t, prm)
            model._last_loads.clear()
            fresh = model.external_force(t, prm)
            np.testing.assert_array_equal(kept, fresh, err_msg=f"t = {t}")
    # past the pulse (0.1 s) and the step (0.05 s): one array for every later time
    first = model.external_force(0.15, params)
    assert model.external_force(0.25, params) is first
    assert model.external_force(0.09, params) is not first
