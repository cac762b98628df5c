"""Animations (``simulate --animate``, ``dynsens export --animate``) and still frames.

A GIF is written for a structure and for a mechanism and read back with Pillow (a GIF of more
than one frame, at most ``MAX_FRAMES``); the frames are evenly spaced and bounded; the worst
instant is the one with the largest stress ratio of the result file's recorded stresses; an
.mp4 without ffmpeg, an unknown format and an existing file without --overwrite are refused
with one message and exit status 2.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import dynsens.cli.simulate  # noqa: F401  (registers the command)
import dynsens.cli.views  # noqa: F401  (registers export)
from conftest import CASES
from dynsens.animate import MAX_FRAMES, animate, frame_indices, render_frame, worst_instant
from dynsens.cli.main import cli
from dynsens.io.scene import read_scene

Image = pytest.importorskip("PIL.Image")
pytest.importorskip("matplotlib")


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_ok(result) -> None:
    assert result.exit_code == 0, f"exit {result.exit_code}\n{result.output}\n{result.exception!r}"


def gif_frames(path: Path) -> int:
    with Image.open(path) as im:
        assert im.format == "GIF"
        return int(im.n_frames)


@pytest.fixture(scope="module")
def truss(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("truss")
    assert_ok(invoke("simulate", CASES / "truss_impact.yaml", "-o", d / "truss.h5", "--no-sensitivities",
                     "--set", "integrator.t_end=0.0015", "--animate", d / "truss.gif"))
    return d / "truss.h5"


def test_structure_animation_is_a_gif_of_every_stored_step(truss: Path) -> None:
    with h5py.File(truss, "r") as f:
        n = len(f["time"])
    assert n == 16 and gif_frames(truss.with_suffix(".gif")) == n


def test_mechanism_animation_from_export(tmp_path: Path) -> None:
    h5 = tmp_path / "lever.h5"
    assert_ok(invoke("simulate", CASES / "hydraulic_lever.yaml", "-o", h5, "--no-sensitivities",
                     "--set", "integrator.t_end=0.02", "--set", "output.history=[q,lam,p]"))
    assert_ok(invoke("export", h5, "--animate", tmp_path / "lever.gif"))
    assert gif_frames(tmp_path / "lever.gif") == 11


def test_frame_count_is_bounded(truss: Path, tmp_path: Path) -> None:
    for n, m in ((5, 200), (1000, 200), (12001, 200), (7, 3)):
        idx = frame_indices(n, m)
        assert len(idx) == min(n, m) and idx[0] == 0 and idx[-1] == n - 1 and np.all(np.diff(idx) > 0)
    assert MAX_FRAMES <= 200
    out = animate(truss, tmp_path / "few.gif", max_frames=4)
    assert gif_frames(out) == 4


def test_worst_instant_is_the_largest_stress(truss: Path, tmp_path: Path) -> None:
    scene = read_scene(truss)
    with h5py.File(truss, "r") as f:
        stress = f["stress"][()]
    assert worst_instant(scene) == int(np.argmax(np.abs(stress).max(axis=1)))
    png = render_frame(scene, worst_instant(scene), tmp_path / "worst.png")
    with Image.open(png) as im:
        assert im.format == "PNG" and im.size[0] > 100


def test_a_3d_structure_is_drawn_in_3d(tmp_path: Path) -> None:
    h5 = tmp_path / "tower.h5"
    assert_ok(invoke("simulate", CASES / "tower_sizing.yaml", "-o", h5, "--no-sensitivities",
                     "--set", "integrator.t_end=0.01", "--animate", tmp_path / "tower.gif"))
    assert gif_frames(tmp_path / "tower.gif") == 6
    scene = read_scene(h5)
    with Image.open(render_frame(scene, worst_instant(scene), tmp_path / "tower.png")) as im:
        assert im.format == "PNG"


def test_bad_animation_requests_are_refused(truss: Path, tmp_path: Path, monkeypatch) -> None:
    from matplotlib import animation
    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    result = invoke("export", truss, "--animate", tmp_path / "a.mp4")
    assert result.exit_code == 2 and "ffmpeg" in result.output and "Traceback" not in result.output
    result = invoke("export", truss, "--animate", tmp_path / "a.avi")
    assert result.exit_code == 2 and ".gif or .mp4" in result.output
    existing = truss.with_suffix(".gif")
    before = existing.read_bytes()
    result = invoke("export", truss, "--animate", existing)
    assert result.exit_code == 2 and "--overwrite" in result.output
    assert existing.read_bytes() == before
    assert not list(tmp_path.iterdir())                     # nothing written for the refused requests
