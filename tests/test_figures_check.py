"""The check that the figures in docs/ are current (scripts/figures.py, `make figures-check`):
a probe value that moved beyond its tolerance, a changed set of keys or a missing figure or
record fails it, naming the figure; round-off below the tolerance does not."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import figures  # noqa: E402


def test_moves_beyond_the_tolerance_are_reported_and_round_off_is_not() -> None:
    rec = {"f": {"values": {"a": 1.0, "b": [2.0, -3.0]}, "nan": math.nan}}
    assert figures.differences(rec, {"f": {"values": {"a": 1.0 + 1e-12, "b": [2.0, -3.0]}, "nan": math.nan}}) == []
    near_zero = figures.differences({"g": [1.0, 1e-12]}, {"g": [1.0, 2e-12]})    # relative to the largest
    assert near_zero == []
    moved = figures.differences(rec, {"f": {"values": {"a": 1.0, "b": [2.0, -3.0 * (1 + 1e-2)]}, "nan": math.nan}})
    assert len(moved) == 1 and moved[0].startswith("f.values.b[1]: -3.0 recorded")
    assert figures.differences({"s": 1.0}, {"s": 1.0 + 2 * figures.RTOL})[0].startswith("s: 1.0 recorded")
    assert figures.differences({"s": math.nan}, {"s": 1.0}) != []
    assert figures.differences(rec, {"f": {"values": {"a": 1.0}, "nan": math.nan}})[0].startswith("f.values: keys")
    assert "entries recorded" in figures.differences({"x": [1.0]}, {"x": [1.0, 2.0]})[0]


def test_every_figure_in_docs_is_covered_and_exists() -> None:
    root = figures.ROOT
    listed = {p for f in figures.FIGURES for p in f.paths}
    shipped = {str(p.relative_to(root)) for ext in ("png", "gif") for p in (root / "docs").rglob(f"*.{ext}")}
    assert shipped == listed


def test_check_fails_on_a_stale_probe_and_a_missing_record(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    fig = figures.Figure("toy", ("docs/fig5.png",), (), lambda: {"value": 2.0})
    monkeypatch.setattr(figures, "FIGURES", (fig,))
    monkeypatch.setattr(figures, "RECORD", tmp_path / "figures.json")
    assert figures.check() == 1 and "run `make figures`" in capsys.readouterr().err
    figures.RECORD.write_text(json.dumps({"figures": {"toy": {"probe": {"value": 2.0}}}}))
    assert figures.check() == 0
    figures.RECORD.write_text(json.dumps({"figures": {"toy": {"probe": {"value": 2.1}}}}))
    assert figures.check() == 1
    err = capsys.readouterr().err
    assert "toy (docs/fig5.png) is stale" in err and "value: 2.1 recorded, 2.0 now" in err


def test_make_accepts_the_statuses_a_figure_allows_and_resumes_from_a_named_figure(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    exit1 = (sys.executable, "-c", "import sys; sys.exit(1)")
    mark = tmp_path / "ran"
    touch = (sys.executable, "-c", f"open({str(mark)!r}, 'w').close()")
    monkeypatch.setattr(figures, "RECORD", tmp_path / "figures.json")
    # an optimization stopped by its iteration limit (status 1) still made its figure
    monkeypatch.setattr(figures, "FIGURES", (figures.Figure("limit", ("p",), (exit1,), lambda: {"v": 1.0},
                                                            statuses=(0, 1)),))
    figures.make()
    assert json.loads(figures.RECORD.read_text())["figures"]["limit"]["probe"] == {"v": 1.0}
    # any other failure stops `make`, naming the figure, and writes no record
    figures.RECORD.unlink()
    failing = figures.Figure("broken", ("p",), (exit1,), lambda: {"v": 1.0})
    monkeypatch.setattr(figures, "FIGURES", (failing, figures.Figure("later", ("q",), (touch,), lambda: {"v": 2.0})))
    with pytest.raises(SystemExit, match="broken: .* exited with status 1"):
        figures.make()
    assert not figures.RECORD.exists() and not mark.exists()
    # resumed from the figure after the one that stopped: the record holds every figure's probe
    figures.make("later")
    assert mark.exists() and set(json.loads(figures.RECORD.read_text())["figures"]) == {"broken", "later"}
    with pytest.raises(SystemExit, match="no such figure"):
        figures.make("nonesuch")


def test_make_builds_figures_side_by_side_with_their_output_in_logs(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    say = [(sys.executable, "-c", f"print('figure {i}')") for i in range(2)]
    monkeypatch.setattr(figures, "ROOT", tmp_path)
    monkeypatch.setattr(figures, "RECORD", tmp_path / "figures.json")
    monkeypatch.setattr(figures, "FIGURES", tuple(figures.Figure(f"f {i}", ("p",), (say[i],), lambda i=i: {"v": i})
                                                  for i in range(2)))
    figures.make(jobs=2)
    assert json.loads(figures.RECORD.read_text())["figures"]["f 1"]["probe"] == {"v": 1}
    for i in range(2):
        assert f"figure {i}" in (tmp_path / "results" / "figure-logs" / f"f_{i}.log").read_text()
