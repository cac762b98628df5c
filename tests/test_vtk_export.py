"""ParaView output (``simulate --vtk``, ``dynsens export --vtk``): the VTU/PVD files read back with
meshio carry the geometry and fields of the HDF5 result file.

Checked against what the files hold independently of the exporter: the node coordinates and
element ends as the case text gives them, the displacement and joint histories in /state, the
recorded quantities (computed by the run's recorder, not by the exporter), and closed forms
(N = σA of a bar; the Euler load P_E = π²EI/L² with the tower's I = 10A²/(8π); the stress
ratio |σ|/235 MPa of the tower's limits; the cylinder's length L0 + stroke).
"""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.optimize  # noqa: F401  (registers the command)
import dynsens.cli.simulate  # noqa: F401  (registers the command)
import dynsens.cli.views  # noqa: F401  (registers export)
from conftest import CASES
from dynsens.cli.main import cli

meshio = pytest.importorskip("meshio")


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_ok(result) -> None:
    assert result.exit_code == 0, f"exit {result.exit_code}\n{result.output}\n{result.exception!r}"


def read_pvd(pvd: Path) -> list[tuple[float, int, Path]]:
    """(time, part, file) of every DataSet of a .pvd collection."""
    root = ET.parse(pvd).getroot()
    return [(float(d.get("timestep")), int(d.get("part")), pvd.parent / d.get("file"))
            for d in root.iter("DataSet")]


def frames(pvd: Path, part: int) -> tuple[np.ndarray, list]:
    """Times and meshes of one part of a collection."""
    rows = [(t, f) for t, p, f in read_pvd(pvd) if p == part]
    return np.array([t for t, _ in rows]), [meshio.read(f) for _, f in rows]


def text(values) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in values]


def cell(mesh, name: str) -> np.ndarray:
    return np.concatenate(mesh.cell_data[name])


@pytest.fixture(scope="module")
def truss(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("truss")
    assert_ok(invoke("simulate", CASES / "truss_impact.yaml", "-o", d / "truss.h5", "--no-sensitivities",
                     "--set", "integrator.t_end=0.003", "--vtk", d / "vtk"))
    return d / "truss.h5", d / "vtk" / "truss.pvd"


def test_truss_geometry_and_fields_equal_the_result_file(truss) -> None:
    h5, pvd = truss
    with h5py.File(h5, "r") as f:
        case = yaml.safe_load(f.attrs["case"])
        time, q, qd, stress = f["time"][()], f["state/q"][()], f["state/qd"][()], f["stress"][()]
        labels = text(f["state"].attrs["q_labels"])
        x = dict(zip(text(f["design/names"][()]), f["design/values"][()]))
    t, meshes = frames(pvd, 0)
    assert np.allclose(t, time) and len(meshes) == len(time) == 31
    nodes = list(case["model"]["nodes"])
    coords = np.array([case["model"]["nodes"][n]["coords"] + [0.0] for n in nodes])
    bars = [e for e in case["model"]["elements"] if e["type"] == "bar"]
    ends = np.array([[nodes.index(a), nodes.index(b)] for a, b in (e["nodes"] for e in bars)])
    area = np.array([x[e["area"]] for e in bars])
    for k, m in enumerate(meshes):
        assert np.array_equal(m.points, coords)                 # undeformed; the motion is point data
        assert np.array_equal(m.cells_dict["line"], ends)
        for j, lab in enumerate(labels):
            node, axis = lab.split(".")
            assert m.point_data["displacement"][nodes.index(node), "xyz".index(axis)] == pytest.approx(q[k, j])
            assert m.point_data["velocity"][nodes.index(node), "xyz".index(axis)] == pytest.approx(qd[k, j])
        fixed = [nodes.index(n) for n in nodes if case["model"]["nodes"][n]["fixed"]]
        assert not m.point_data["displacement"][fixed].any()
        assert np.allclose(cell(m, "stress"), stress[k], rtol=1e-12, atol=1e-9)
        assert np.allclose(cell(m, "axial_force"), stress[k] * area, rtol=1e-10, atol=1e-6)
        assert "stress_ratio" not in m.cell_data             # truss_impact defines no stress limits
    assert np.abs(stress).max() > 1.0                        # the fields compared are not all zero


def test_tower_stress_and_buckling_ratios_follow_its_limits(tmp_path: Path) -> None:
    h5 = tmp_path / "tower.h5"
    assert_ok(invoke("simulate", CASES / "tower_sizing.yaml", "-o", h5, "--no-sensitivities",
                     "--set", "integrator.t_end=0.03"))
    assert_ok(invoke("export", h5, "--vtk", tmp_path / "vtk"))
    with h5py.File(h5, "r") as f:
        case = yaml.safe_load(f.attrs["case"])
        x = dict(zip(text(f["design/names"][()]), f["design/values"][()]))
        n_steps = len(f["time"])
    _, meshes = frames(tmp_path / "vtk" / "tower.pvd", 0)
    assert len(meshes) == n_steps
    m = meshes[-1]
    nodes = case["model"]["nodes"]
    bars = [e for e in case["model"]["elements"] if e["type"] == "bar"]
    A = np.array([x[f"A[{e['name']}]"] for e in bars])
    L = np.array([np.linalg.norm(np.subtract(nodes[e["nodes"][1]]["coords"], nodes[e["nodes"][0]]["coords"]))
                  for e in bars])
    P_euler = np.pi ** 2 * 210000.0 * (A ** 2 * 10 / (8 * np.pi)) / L ** 2
    sigma, N = cell(m, "stress"), cell(m, "axial_force")
    assert np.allclose(N, sigma * A, rtol=1e-10)
    assert np.allclose(cell(m, "stress_ratio"), np.abs(sigma) / 235.0, rtol=1e-12)
    assert np.allclose(cell(m, "buckling_ratio"), -N / P_euler, rtol=1e-10)
    assert np.abs(sigma).max() > 1.0


def test_mechanism_bodies_joints_and_cylinder_equal_the_result_file(tmp_path: Path) -> None:
    h5 = tmp_path / "lever.h5"
    assert_ok(invoke("simulate", CASES / "hydraulic_lever.yaml", "-o", h5, "--no-sensitivities",
                     "--set", "integrator.t_end=0.1", "--vtk", tmp_path / "vtk"))
    pvd = tmp_path / "vtk" / "lever.pvd"
    with h5py.File(h5, "r") as f:
        time, q = f["time"][()], f["state/q"][()]
        force, pivot, p1, p2, stroke = (f[k][()] for k in ("cylinder_force", "pivot_force", "pressure_1",
                                                            "pressure_2", "stroke"))
    assert {p for _, p, _ in read_pvd(pvd)} == {0, 1, 2}    # bodies, joints, cylinders
    t, bodies = frames(pvd, 0)
    _, joints = frames(pvd, 1)
    _, cylinders = frames(pvd, 2)
    assert np.allclose(t, time)
    for k in (0, len(time) // 2, len(time) - 1):
        b = bodies[k]
        assert np.allclose(b.points[0], q[k, :3])                          # the lever's centre of mass
        assert np.allclose(b.points[-2:], [[0, 0, 0], [300, -700, 0]])    # ground markers Z, A
        # the lever's markers Z, B, tip lie on one line through the centre at 750 mm, l_B - 750, 750
        arm = b.points[1:4] - b.points[0]
        assert np.allclose(np.linalg.norm(arm, axis=1), [750, 50, 750])
        assert joints[k].point_data["reaction_force_norm"][0] == pytest.approx(pivot[k], rel=1e-10)
        assert np.allclose(joints[k].points[0], [0, 0, 0], atol=1e-3)     # the pivot at Z (up to the drift)
        c = cylinders[k]
        assert cell(c, "force")[0] == pytest.approx(force[k], rel=1e-12)
        assert cell(c, "pressure_1")[0] == pytest.approx(p1[k], rel=1e-12)
        assert cell(c, "pressure_2")[0] == pytest.approx(p2[k], rel=1e-12, abs=1e-15)
        length = np.linalg.norm(c.points[1] - c.points[0])
        assert length == pytest.approx(620.0 + stroke[k], rel=1e-9)      # length_0 + stroke
    assert stroke[-1] > 1.0 and force.max() > 1.0


def test_optimization_file_exports_start_and_optimum(tmp_path: Path) -> None:
    out = tmp_path / "opt.h5"
    result = invoke("optimize", CASES / "truss_lightweight.yaml", "-o", out, "--maxiter", "2", "--no-verify",
                    "--set", "integrator.t_end=0.003")
    assert result.exit_code in (0, 1), result.output
    assert_ok(invoke("export", out, "--vtk", tmp_path / "vtk"))
    with h5py.File(out, "r") as f:
        x0, x_opt = f["optimization/initial/x"][()], f["optimization/optimum/x"][()]
        q_start = f["optimization/initial/state/q"][()]
        q_opt = f["optimization/optimum/state/q"][()]
    assert not np.allclose(x0, x_opt)                         # two different designs ...
    for label, q in (("start", q_start), ("optimum", q_opt)):
        _, meshes = frames(tmp_path / "vtk" / f"opt_{label}.pvd", 0)
        u = meshes[-1].point_data["displacement"]
        assert np.abs(u).max() == pytest.approx(np.abs(q[-1]).max(), rel=1e-12)   # ... each its own run


def test_every_nth_instant_and_the_last(tmp_path: Path, truss) -> None:
    h5, _ = truss
    assert_ok(invoke("export", h5, "--vtk", tmp_path, "--vtk-every", "7"))
    with h5py.File(h5, "r") as f:
        time = f["time"][()]
    t, meshes = frames(tmp_path / "truss.pvd", 0)
    assert len(time) == 31 and np.array_equal(t, time[[0, 7, 14, 21, 28, 30]])
    result = invoke("export", h5, "--vtk", tmp_path / "x", "--vtk-every", "0")
    assert result.exit_code == 2 and "--vtk-every" in result.output


def test_missing_meshio_names_the_extra(monkeypatch, tmp_path: Path, truss) -> None:
    h5, _ = truss
    monkeypatch.setitem(sys.modules, "meshio", None)         # import meshio raises ImportError
    result = invoke("export", h5, "--vtk", tmp_path / "vtk")
    assert result.exit_code == 2
    assert "pip install 'dynsens[vtk]'" in result.output
    assert not (tmp_path / "vtk").exists()
    result = invoke("simulate", CASES / "truss_impact.yaml", "-o", tmp_path / "x.h5", "--vtk", tmp_path / "vtk")
    assert result.exit_code == 2 and "dynsens[vtk]" in result.output
    assert not (tmp_path / "x.h5").exists()                 # refused before the run


def test_existing_output_needs_overwrite(tmp_path: Path, truss) -> None:
    h5, _ = truss
    assert_ok(invoke("export", h5, "--vtk", tmp_path))
    pvd = tmp_path / "truss.pvd"
    before = pvd.read_bytes()
    result = invoke("export", h5, "--vtk", tmp_path)
    assert result.exit_code == 2
    assert "exist" in result.output and "--overwrite" in result.output and "Traceback" not in result.output
    assert pvd.read_bytes() == before
    (tmp_path / "truss" / "stale.vtu").write_text("x")
    assert_ok(invoke("export", h5, "--vtk", tmp_path, "--overwrite"))
    assert not (tmp_path / "truss" / "stale.vtu").exists()       # the data folder is replaced whole
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []   # no temporary left


def test_a_file_without_the_displacement_history_is_refused(tmp_path: Path) -> None:
    h5 = tmp_path / "bare.h5"
    assert_ok(invoke("simulate", CASES / "truss_impact.yaml", "-o", h5, "--no-sensitivities",
                     "--set", "integrator.t_end=0.001", "--set", "output.history=none"))
    result = invoke("export", h5, "--vtk", tmp_path / "vtk")
    assert result.exit_code == 2
    assert str(h5) in result.output and "state/q" in result.output and "output.history" in result.output
    assert not (tmp_path / "vtk" / "bare.pvd").exists()
    result = invoke("export", CASES / "truss_impact.yaml", "--vtk", tmp_path / "vtk")
    assert result.exit_code == 2 and "expected a dynsens result file" in result.output
    result = invoke("export", h5)
    assert result.exit_code == 2 and "--vtk" in result.output
    springs = tmp_path / "sdof.h5"                            # a spring-mass model has nothing to draw
    assert_ok(invoke("simulate", CASES / "sdof_step.yaml", "-o", springs, "--no-sensitivities",
                     "--set", "output.history=[q]"))
    result = invoke("export", springs, "--vtk", tmp_path / "vtk")
    assert result.exit_code == 2 and "expected bars or beams" in result.output
