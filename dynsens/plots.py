"""Plots of recorded quantities (``simulate --plots``, ``optimize --plots``), with units and events.

Quantities that share a unit share a panel (the weir: forces in N, pressures in MPa, the stroke
in mm, the rack angle in rad); events are dashed vertical lines; the responses that read a
plotted quantity are marked on it (a value as a dot at its time, a KS maximum as a dotted
horizontal line).  matplotlib is needed (``pip install 'dynsens[plot]'``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .timeloop.records import RecordedQuantity

MAX_LEGEND = 12     # curves in a panel named one by one; beyond, the largest (see _largest_named)


@dataclass(frozen=True)
class Marker:
    """A response shown on the panel of quantity ``quantity``: at time ``t`` (a point) or, with
    ``t`` None, as a level over the whole run."""

    quantity: str
    name: str
    value: float
    t: float | None = None
    level: float | None = None      # where a level is drawn, if not at value (−|peak| of a negative peak)


@dataclass
class Run:
    """What one curve set shows: a name, the recorded quantities and the events that fired."""

    name: str
    quantities: dict[str, RecordedQuantity]
    events: dict[str, float]


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        from .errors import DynsensError
        raise DynsensError("plots need matplotlib: pip install matplotlib (or 'dynsens[plot]')") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def panels(quantities: dict[str, RecordedQuantity]) -> list[tuple[str, list[str]]]:
    """(unit, quantity names) per panel, in the order the quantities come."""
    out: dict[str, list[str]] = {}
    for name, q in quantities.items():
        out.setdefault(q.unit, []).append(name)
    return list(out.items())


def plot_runs(runs: Sequence[Run], path: str | Path, title: str, markers: Sequence[Marker] = ()) -> Path | None:
    """One figure: a panel per unit, every run's curves (solid, dashed, ...), events and markers.
    Returns the file written, or None when there is nothing recorded."""
    if not runs or not runs[0].quantities:
        return None
    plt = _pyplot()
    groups = panels(runs[0].quantities)
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 2.4 * len(groups) + 0.8), sharex=True, squeeze=False)
    styles = ["-", "--", ":", "-."]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (unit, names) in zip(axes[:, 0], groups):
        for k, run in enumerate(runs):
            for c, name in enumerate(names):
                q = run.quantities.get(name)
                if q is None:
                    continue
                v = q.value if q.value.ndim == 2 else q.value[:, None]
                labels = list(q.components) or [""]
                for j in range(v.shape[1]):
                    lab = q.label + (f" {labels[j]}" if labels[j] else "")
                    ax.plot(q.time, v[:, j], styles[k % len(styles)], color=colours[(c + j) % len(colours)],
                            lw=1.2, label=lab + (f" ({run.name})" if len(runs) > 1 else ""))
            for ev, t in run.events.items():
                ax.axvline(t, color="grey", ls=styles[k % len(styles)], lw=0.8)
                if ax is axes[0, 0]:
                    ax.annotate(f"{ev} at {t:.4g} s" + (f" ({run.name})" if len(runs) > 1 else ""),
                                (t, 1.0 + 0.08 * k), xycoords=("data", "axes fraction"), fontsize=7,
                                ha="right", va="bottom", annotation_clip=False)
        # one label per point or level
        shown: dict[tuple[float | None, float, float], list[str]] = {}
        for mk in markers:
            key = (mk.t, mk.value, mk.value if mk.level is None else mk.level)
            if mk.quantity in names and np.isfinite(mk.value) and mk.name not in shown.get(key, []):
                shown.setdefault(key, []).append(mk.name)
        for (at, value, level), who in shown.items():
            text = f"{', '.join(who)} = {value:.5g} {unit}"
            if at is None:
                ax.axhline(level, color="k", ls=":", lw=0.8)
                ax.annotate(text, (0.01, level), xycoords=("axes fraction", "data"), fontsize=7,
                            va="bottom" if level >= 0 else "top")
            else:
                ax.plot([at], [value], "ko", ms=4)
                ax.annotate(" " + text, (at, value), fontsize=7,
                            ha="right" if at > 0.5 * (ax.get_xlim()[0] + ax.get_xlim()[1]) else "left")
        ax.set_ylabel(f"[{unit}]" if unit else "(case units)")
        ax.grid(True, alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        if len(handles) <= MAX_LEGEND:
            ax.legend(fontsize=7, loc="best")
        else:    # e.g. the stresses of every bar: name the largest, grey the others
            ax.legend(*_largest_named(handles, labels, plt), fontsize=7, loc="best")
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _largest_named(handles: list, labels: list[str], plt: Any, keep: int = 6) -> tuple[list, list[str]]:
    """Legend of a crowded panel: the ``keep`` curves of largest peak |value| in colour with
    their names, every other curve drawn light grey under one entry."""
    peaks = [float(np.nanmax(np.abs(h.get_ydata()))) if len(h.get_ydata()) else 0.0 for h in handles]
    order = np.argsort(peaks)[::-1]
    top = [int(i) for i in order[:keep]]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, i in enumerate(top):                     # distinct colours for the named ones
        handles[i].set_color(colours[k % len(colours)])
    for i in order[keep:]:
        handles[i].set_color("0.75")
        handles[i].set_linewidth(0.8)
        handles[i].set_zorder(1)
    rest = plt.Line2D([], [], color="0.75", lw=0.8)
    return ([handles[i] for i in top] + [rest],
            [labels[i] for i in top] + [f"{len(handles) - keep} others (smaller peaks)"])


def response_markers(case: Any, result: Any) -> list[Marker]:
    """Markers for the responses of ``case`` that read a recorded quantity of ``result``: values
    at a time, at an event or at the end as points; KS, max and min of the quantity itself (not of
    a ratio of it) as levels."""
    from .responses.base import ValueAt
    from .responses.sizing import Aggregate
    from .timeloop.records import reads_in_own_unit
    by_output: dict[int, list[str]] = {}
    for name, q in result.quantities.items():
        by_output.setdefault(q.output_id, []).append(name)
    out = []
    for r in case.new_response_set(record=False).responses:
        rv = result.responses.get(r.name)
        if rv is None or rv.missing:
            continue
        value = float(np.real(rv.value))
        if isinstance(r, ValueAt):
            t = r.time if r.time is not None and r.event is None else \
                result.events.get(r.event, None) if r.event is not None else \
                (next(reversed(result.events.values())) if result.events else float(result.time[-1]))
            for name in by_output.get(r.output_ids[0], []):
                if t is not None:
                    out.append(Marker(name, r.name, value, float(t)))
        elif isinstance(r, Aggregate) and reads_in_own_unit(r):
            for oid in r.output_ids:
                for name in by_output.get(oid, []):
                    out.append(Marker(name, r.name, value,
                                      level=_level(r, value, result.quantities[name].value)))
    return out


def _level(r: Any, value: float, v: np.ndarray) -> float:
    """Where the aggregate ``r`` (value ``value``) lies on the plotted quantity v: an absolute
    maximum |v| at the sign of the peak it measures, a maximum of −v at −value."""
    sides = sorted({float(s) for t in r.terms for s in np.ravel(t.sides)})
    v = np.real(np.asarray(v))
    if not v.size or len(sides) == 1:
        return sides[0] * value
    # the side whose sampled extreme is the aggregate's (KS lies a little above it)
    extremes = {s: r.sense * np.max(r.sense * s * v) for s in sides}
    side = min(extremes, key=lambda s: abs(extremes[s] - value))
    return side * value
