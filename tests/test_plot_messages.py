"""Plots that misled (issue 37, "Messages and plots that mislead"); each test failed before its fix:

- a case without ``output.quantities`` got its stress panel labelled ``[-]`` (the unit of the
  stress *ratio* response reading it) while the values are stresses in the case's units, and
  the buckling ratios were drawn on that same panel;
- all bar stresses shared one legend entry, coloured as the first curve;
- an absolute KS level was drawn at +|peak| when the peak is negative;
- the optimization history drew the 1e-16 floor of a zero violation as data;
- the optimum plot without recorded quantities was titled with unnamed numbers.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

import dynsens
from dynsens.timeloop.records import quantities_read_by

CASES = Path(__file__).resolve().parents[1] / "cases"
plt = pytest.importorskip("matplotlib.pyplot")


def _truss_without_quantities() -> dynsens.Case:
    return dynsens.load_case(CASES / "truss_lightweight.yaml", ["output.quantities=[]"])


def test_a_ratio_response_does_not_lend_its_unit_to_the_quantity_it_reads() -> None:
    case = _truss_without_quantities()
    units = {s.name: s.unit for s in quantities_read_by(case.new_response_set(record=False))}
    assert units["stress_ks_quantity"] == ""            # stresses in the case's units, not "-"
    assert units["buckling_ks_quantity"] == "-"         # −N/P_E is a ratio itself
    assert units["t4.y.displacement"] == "mm"            # tip_ks is a KS of the displacement itself


def test_an_absolute_ks_level_lies_at_the_sign_of_its_peak() -> None:
    from dynsens.plots import response_markers
    case = _truss_without_quantities()
    result = dynsens.run_case(case, sensitivities=False)
    tip = result.quantities["t4.y.displacement"].value
    assert np.min(tip) < -abs(np.max(tip))              # the tip moves down
    marker = next(m for m in response_markers(case, result) if m.name == "tip_ks")
    assert marker.value > 0 and marker.level == pytest.approx(-marker.value)
    assert abs(marker.level - np.min(tip)) < 0.05 * abs(np.min(tip))


def test_a_crowded_panel_names_its_largest_curves_and_greys_the_others() -> None:
    from dynsens.plots import _largest_named
    fig, ax = plt.subplots()
    t = np.linspace(0.0, 1.0, 20)
    amplitude = np.random.default_rng(1).permutation(16) + 1.0
    for k, a in enumerate(amplitude):
        ax.plot(t, a * np.sin(3 * t), label=f"bar{k}")
    handles, labels = ax.get_legend_handles_labels()
    shown, names = _largest_named(handles, labels, plt)
    largest = [f"bar{k}" for k in np.argsort(amplitude)[::-1][:6]]
    assert names == largest + ["10 others (smaller peaks)"]
    colours = [h.get_color() for h in shown[:6]]
    assert len(set(colours)) == 6                       # six distinct colours for six names
    assert sum(h.get_color() == "0.75" for h in handles) == 10
    plt.close(fig)


def test_a_zero_violation_is_not_drawn_as_a_number() -> None:
    from dynsens.optimize.plots import ZERO_LABEL, _positive_on_log
    fig, ax = plt.subplots()
    _positive_on_log(ax, np.arange(4), np.array([3e-2, 1e-4, 0.0, 0.0]), "C0")
    data = [line for line in ax.get_lines() if line.get_label() != ZERO_LABEL]
    y = np.concatenate([line.get_ydata() for line in data])
    assert np.nanmin(y) == pytest.approx(1e-4)          # no 1e-16 floor among the data
    zeros = [line for line in ax.get_lines() if line.get_label() == ZERO_LABEL]
    assert len(zeros) == 1 and list(zeros[0].get_xdata()) == [2, 3]
    plt.close(fig)


def test_the_optimum_fallback_title_names_the_design(tmp_path: Path) -> None:
    from dynsens.optimize.plots import _named_design
    with h5py.File(tmp_path / "o.h5", "w") as f:
        f["design/names"] = [n.encode() for n in ("A1", "A2", "c", "d", "e", "f", "g")]
        f.create_group("optimization").attrs["design_units"] = '["mm2", "mm2", "", "", "", "", ""]'
        text = _named_design(f, np.array([12.345, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]))
    assert text.startswith("best design: A1 = 12.35 mm2, A2 = 2 mm2, c = 3") and "(1 more)" in text

