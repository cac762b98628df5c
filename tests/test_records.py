"""Recorded quantities (output.quantities) against the responses that read the same quantity,
and the result file as pandas and xarray read it."""
import copy

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.io.hdf5 import write_result

WEIR = CASES / "tyrolean_weir.yaml"


def sdof_case(**extra):
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["integrator"]["t_end"] = 1.0
    raw["output"] = {"history": ["q"], "quantities": [
        {"name": "u", "quantity": {"dof": "u"}, "unit": "m", "label": "displacement", "sensitivity": True},
        {"name": "spring_force", "quantity": {"element": "spring", "kind": "force"}, "unit": "N"}]}
    raw["responses"] += [
        {"name": "u_at_half", "type": "value", "quantity": {"dof": "u"}, "time": 0.5, "unit": "m"},
        {"name": "u_int", "type": "integral", "quantity": {"dof": "u"}},
        {"name": "f_end", "type": "value", "quantity": {"element": "spring", "kind": "force"}}]
    for k, v in extra.items():
        raw[k] = v
    return dynsens.load_case_dict(raw, "sdof_records")


def test_recorded_quantities_agree_with_the_responses_reading_them():
    res = dynsens.run_case(sdof_case())
    u, fs = res.quantities["u"], res.quantities["spring_force"]
    r = res.responses
    assert np.array_equal(u.time, res.time) and u.unit == "m" and u.label == "displacement"
    assert np.array_equal(u.value, res.history["q"][:, 0])                 # the state itself
    i = int(np.argmin(abs(res.time - 0.5)))
    assert res.time[i] == pytest.approx(0.5, abs=1e-12)
    assert u.value[i] == pytest.approx(r["u_at_half"].value, rel=1e-14)
    assert np.allclose(u.gradient[i], r["u_at_half"].gradient, rtol=1e-12, atol=0)
    assert np.allclose(u.gradient[-1], r["q_end"].gradient, rtol=1e-12, atol=0)
    assert np.sum(np.diff(u.time) * 0.5 * (u.value[1:] + u.value[:-1])) == pytest.approx(r["u_int"].value, rel=1e-12)
    assert fs.value[-1] == pytest.approx(r["f_end"].value, rel=1e-14) and fs.gradient is None
    assert fs.value[-1] == pytest.approx(50.0 * u.value[-1], rel=1e-12)     # k u
    ks = r["q_ks"].value                                                     # KS ≥ max, within ln N / ρ
    assert u.value.max() <= ks <= u.value.max() + np.log(len(u.value)) / 100.0


def test_weir_records_what_its_responses_read_up_to_the_event():
    raw = yaml.safe_load(WEIR.read_text())
    raw["events"][0]["value"] = -0.4780        # the rack reaches −27.38° after ≈ 0.1 s
    raw["output"]["quantities"][1]["sensitivity"] = True                     # the stroke
    res = dynsens.run_case(dynsens.load_case_dict(raw, "weir_short"))
    q, r = res.quantities, res.responses
    assert res.status == "terminated" and len(q["stroke"].value) == len(res.time)
    assert q["rack_angle"].value[0] == pytest.approx(r["theta_0"].value, rel=1e-14)
    # the event instant lies in the last step: the response is interpolated between the last two
    lo, hi = sorted(q["stroke"].value[-2:])
    assert lo <= r["stroke"].value <= hi
    # fixed-time gradient at the event = the recorded gradients interpolated at the same fraction
    theta = (r["t_F"].value - res.time[-2]) / (res.time[-1] - res.time[-2])
    g = q["stroke"].gradient
    assert np.allclose(r["stroke_fixed_time"].gradient, g[-2] + theta * (g[-1] - g[-2]), rtol=1e-10)
    reactions = np.stack([q[f"reaction_{j}"].value for j in "ZABP"])[:, :-1]   # KS reads up to the event
    assert reactions.max() <= r["ks_force"].value <= reactions.max() + np.log(reactions.size) / 200.0
    assert q["cylinder_force"].unit == "N" and q["pressure_1"].unit == "MPa"


def test_multi_component_quantity_and_component_subset():
    raw = yaml.safe_load(WEIR.read_text())
    raw["integrator"]["t_end"] = 0.01
    raw["output"]["quantities"] = [
        {"name": "load_point", "quantity": {"marker": "rack.load", "kind": "position"}, "unit": "mm"},
        {"name": "Z_xy", "quantity": {"joint": "Z", "kind": "reaction_force"}, "component": ["Fx", "Fy"]}]
    res = dynsens.run_case(dynsens.load_case_dict(raw, "weir_short"))
    assert res.quantities["load_point"].value.shape == (len(res.time), 3)
    assert res.quantities["Z_xy"].value.shape == (len(res.time), 2)
    assert res.quantities["Z_xy"].components[0].endswith("Fx")


@pytest.mark.parametrize("entry, path, words", [
    ({"name": "time", "quantity": {"dof": "u"}}, "output.quantities[0].name", "reserved"),
    ({"name": "x y", "quantity": {"dof": "u"}}, "output.quantities[0].name", "identifier"),
    ({"name": "a", "quantity": {"dof": "w"}}, "output.quantities[0].quantity.dof", "unknown"),
    ({"name": "a", "quantity": {"dof": "u"}, "component": "z"}, "output.quantities[0].component", "not found"),
    ({"name": "a", "quantity": {"dof": "u"}, "colour": "red"}, "output.quantities[0].colour", "unknown key"),
])
def test_bad_quantities_are_named_by_their_path(entry, path, words):
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["output"] = {"quantities": [entry]}
    with pytest.raises(dynsens.CaseError) as err:
        dynsens.load_case_dict(raw, "bad.yaml")
    assert path in str(err.value) and words in str(err.value)


@pytest.fixture(scope="module")
def sdof_file(tmp_path_factory):
    case = sdof_case()
    res = dynsens.run_case(case)
    path = tmp_path_factory.mktemp("rec") / "sdof.h5"
    write_result(path, res, case)
    return path, res


def test_read_result_arrays_and_dataframe(sdof_file):
    import pandas as pd     # in the test extra: a missing package fails here, it is not skipped
    path, res = sdof_file
    out = dynsens.read_result(path)
    assert np.array_equal(out.time, res.time) and out.units["u"] == "m"
    assert np.array_equal(out.quantities["spring_force"], res.quantities["spring_force"].value)
    assert np.array_equal(out.quantity_gradients["u"], res.quantities["u"].gradient)
    assert out.responses["q_end"]["value"] == res.responses["q_end"].value
    df = out.to_dataframe()
    assert isinstance(df, pd.DataFrame) and df.index.name == "time"
    assert list(df.columns) == ["u", "spring_force"] and df.attrs["units"]["spring_force"] == "N"
    assert df["u"].iloc[-1] == res.quantities["u"].value[-1]
    assert list(out.to_dataframe("state").columns) == ["q[u]"]


def test_xarray_opens_the_file_on_a_real_time_axis(sdof_file):
    import h5netcdf  # noqa: F401  (the test extra installs both)
    import xarray as xr
    path, res = sdof_file
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert list(ds["u"].dims) == ["time"] and np.array_equal(ds["time"].values, res.time)
        assert ds["time"].attrs["units"] == "s" and ds["spring_force"].attrs["units"] == "N"
        assert list(ds["design_variable"].values) == ["m", "c", "k"]
        assert not any(d.startswith("phony") for d in ds.dims)
    with xr.open_dataset(path, engine="h5netcdf", group="quantity_gradients") as ds:
        assert ds["u"].dims == ("time", "design_variable")
    with xr.open_dataset(path, engine="h5netcdf", group="state") as ds:
        assert ds["q"].dims == ("time", "dof")
    ds = dynsens.read_result(path).to_xarray()
    assert ds["u"].attrs["units"] == "m" and ds["d_u"].dims == ("time", "design_variable")
    assert float(ds["u"].sel(time=0.5, method="nearest")) == pytest.approx(res.responses["u_at_half"].value)


def test_a_case_without_quantities_records_what_its_responses_read(tmp_path):
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["integrator"]["t_end"] = 0.1
    raw.pop("output", None)                 # the case names no quantities of its own
    case = dynsens.load_case_dict(copy.deepcopy(raw), "plain")
    res = dynsens.run_case(case)
    assert list(res.quantities) == ["u.displacement"]          # read by q_end and q_ks, recorded once
    assert res.quantities["u.displacement"].unit == "m"
    assert res.quantities["u.displacement"].value[-1] == res.responses["q_end"].value
    assert dynsens.run_case(case, record=False).quantities == {}
    write_result(tmp_path / "plain.h5", dynsens.run_case(case, record=False), case)
    out = dynsens.read_result(tmp_path / "plain.h5")
    assert out.quantities == {} and out.state["q"].shape == (101, 1)


def test_a_file_of_the_earlier_layout_still_reads(tmp_path):
    """Files written before the dimension scales: /time, /state, /design, /responses, /stats."""
    import h5py
    with h5py.File(tmp_path / "old.h5", "w") as f:
        f.attrs["status"] = "completed"
        f.create_dataset("time", data=np.linspace(0, 1, 11))
        f.create_group("state").create_dataset("q", data=np.ones((11, 2)))
        f.create_group("design").create_dataset("names", data=np.array(["a"], dtype=h5py.string_dtype()))
        rg = f.create_group("responses").create_group("r")
        rg.create_dataset("value", data=2.0)
        rg.attrs["unit"] = "m"
        f.create_group("stats").attrs["steps"] = 10
    out = dynsens.read_result(tmp_path / "old.h5")
    assert out.quantities == {} and out.state["q"].shape == (11, 2) and out.responses["r"]["value"] == 2.0
    assert out.design_names == ["a"] and out.stats["steps"] == 10
    assert list(out.to_dataframe("state").columns) == ["q[0]", "q[1]"]


def test_recorded_gradient_histories_match_central_differences_of_the_whole_run():
    """An independent check of the recorded sensitivity path (quantities no response reads:
    the cylinder force and the rod-side pressure), at every step of a short weir run."""
    raw = yaml.safe_load(WEIR.read_text())
    raw["integrator"]["t_end"] = 0.03
    raw["output"]["quantities"] = [
        {"name": "force", "quantity": {"element": "cylinder", "kind": "force"}, "sensitivity": True},
        {"name": "p2", "quantity": {"element": "cylinder", "kind": "pressure_2"}, "sensitivity": True},
        {"name": "force_values", "quantity": {"element": "cylinder", "kind": "force"}}]
    raw["sensitivity"]["partials"] = "complex"
    case = dynsens.load_case_dict(raw, "weir_short")
    res = dynsens.run_case(case)
    q = res.quantities
    assert np.array_equal(q["force"].value, q["force_values"].value) and q["force_values"].gradient is None
    x0, rel = case.x0, 1e-5
    for j in range(x0.size):
        h = rel * abs(x0[j])
        runs = [dynsens.run_case(case, x0 + s * h * np.eye(x0.size)[j], sensitivities=False) for s in (1, -1)]
        for name in ("force", "p2"):
            fd = (runs[0].quantities[name].value - runs[1].quantities[name].value) / (2 * h)
            g = q[name].gradient[:, j]
            scale = np.max(np.abs(g))
            assert scale > 0, (name, j)
            # central differences agree to 1.3e-6 of the largest gradient (worst: p2 against theta_AZ)
            assert np.max(np.abs(fd - g)) <= 1e-5 * scale, (name, j, np.max(np.abs(fd - g)) / scale)


def _counting(case, calls):
    """The case with every output's evaluations counted in ``calls`` (by output id)."""
    import dataclasses

    make = case._make_responses

    def made(record):
        rs = make(record)
        for oid, o in enumerate(rs.outputs):
            def fn(t, s, prm, _fn=o.fn, _oid=oid):
                calls[_oid] = calls.get(_oid, 0) + 1
                return _fn(t, s, prm)
            rs.outputs[oid] = dataclasses.replace(o, fn=fn)
        return rs
    return dataclasses.replace(case, _make_responses=made)


def test_outputs_only_a_recorded_quantity_reads_are_evaluated_only_when_recording():
    raw_extra = {"name": "a", "quantity": {"dof": "u", "kind": "acceleration"}, "unit": "m/s2"}
    raw = yaml.safe_load(sdof_case().text)
    raw["output"]["quantities"].append(raw_extra)
    case = dynsens.load_case_dict(raw, "sdof_records")
    calls: dict[int, int] = {}
    counted = _counting(case, calls)
    rs = case.new_response_set()
    a_id = next(s.output_id for s in case.quantities if s.name == "a")
    read = {oid for r in rs.responses for oid in r.output_ids}
    assert a_id not in read
    recorded = dynsens.run_case(counted)
    assert calls.get(a_id, 0) > 0 and "a" in recorded.quantities
    assert recorded.quantities["a"].value.shape == recorded.time.shape
    calls.clear()
    bare = dynsens.run_case(counted, history=())
    assert calls.get(a_id, 0) == 0 and all(calls.get(oid, 0) > 0 for oid in read)
    assert bare.quantities == {}
    for name, r in recorded.responses.items():          # the responses do not notice
        assert np.array_equal(np.atleast_1d(r.value), np.atleast_1d(bare.responses[name].value)), name
        assert np.array_equal(r.gradient, bare.responses[name].gradient), name
