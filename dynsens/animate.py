"""Animations and still frames of a run: the structure or mechanism moving, with the time on screen.

A structure is drawn deformed (displacements magnified to a readable size, the factor in the
title), each member coloured by its stress ratio (or its stress when the case defines no
limits) on one colour scale for the whole run, with a colour bar.  A mechanism is drawn as its
bodies (centre of mass joined to the markers), ground points, joints and cylinders.  A model
that stays in the x–y plane is drawn in 2D, any other in 3D.

At most ``max_frames`` evenly spaced stored instants are drawn (the last always), so a file
stays small however fine the time step.  ``.gif`` is written with Pillow, ``.mp4`` with
ffmpeg (which must be installed); matplotlib is the optional ``plot`` extra.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from .errors import DynsensError
from .io.paths import atomic_path, check_output_path
from .io.reader import MissingExtraError
from .io.scene import Scene, read_scene, stored_runs

MAX_FRAMES = 200
FORMATS = (".gif", ".mp4")


class AnimationError(DynsensError):
    """An animation cannot be written (format, writer)."""


def _pyplot() -> Any:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingExtraError("animations need matplotlib: pip install 'dynsens[plot]'") from None
    return plt


def check_animation_path(out: str | Path, overwrite: bool = False) -> Path:
    """Raise unless ``out`` is a writable ``.gif`` or ``.mp4`` file whose writer is available."""
    out = Path(out)
    if out.suffix.lower() not in FORMATS:
        raise AnimationError(f"--animate: expected a file ending in .gif or .mp4, found {out.name!r}")
    check_output_path(out, overwrite, option="--animate")
    _pyplot()
    from matplotlib import animation
    if out.suffix.lower() == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise AnimationError(f"--animate {out}: an .mp4 is written by ffmpeg, found no ffmpeg on the PATH "
                             "(install ffmpeg, or write a .gif)")
    return out


def animate(path: str | Path, out: str | Path, overwrite: bool = False, max_frames: int = MAX_FRAMES,
            fps: int = 20) -> Path:
    """Animate the run of result file ``path`` (the optimum of an optimization file) into ``out``
    (``.gif`` or ``.mp4``); returns ``out``."""
    out = check_animation_path(out, overwrite)
    runs = stored_runs(path)
    label = "optimum" if "optimum" in runs else next(iter(runs))
    return animate_scene(read_scene(path, runs[label], label), out, overwrite, max_frames, fps)


def frame_indices(n: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """At most ``max_frames`` evenly spaced indices of ``n`` instants, the first and last included."""
    return np.unique(np.linspace(0, n - 1, max(1, min(n, max_frames))).round().astype(int))


def worst_instant(scene: Scene) -> int:
    """Index of the instant with the largest stress ratio of any member (largest |stress|
    without limits; the last instant for a mechanism)."""
    if scene.kind != "structure":
        return len(scene.time) - 1
    data = scene.parts[0].cell_data
    v = data["stress_ratio"] if "stress_ratio" in data else np.abs(data["stress"])
    v = np.where(np.isfinite(v), v, -np.inf)
    return int(np.argmax(v.max(axis=1)))


def animate_scene(scene: Scene, out: str | Path, overwrite: bool = False, max_frames: int = MAX_FRAMES,
                  fps: int = 20) -> Path:
    """Write the animation of ``scene`` to ``out`` (atomically); returns ``out``."""
    out = check_animation_path(out, overwrite)
    plt = _pyplot()
    from matplotlib import animation
    frames = frame_indices(len(scene.time), max_frames)
    drawing = Drawing(plt, scene, frames)
    anim = animation.FuncAnimation(drawing.fig, drawing.update, frames=list(frames), blit=False)
    writer = animation.PillowWriter(fps=fps) if out.suffix.lower() == ".gif" else \
        animation.FFMpegWriter(fps=fps, bitrate=800)
    try:
        with _atomic_named(out, overwrite) as tmp:
            anim.save(str(tmp), writer=writer, dpi=drawing.dpi)
    finally:
        plt.close(drawing.fig)
    return out


def render_frame(scene: Scene, index: int, out: str | Path, overwrite: bool = False) -> Path:
    """A PNG of ``scene`` at stored instant ``index`` (same drawing and colour scale as the
    animation); returns ``out``."""
    out = check_output_path(out, overwrite, option="PNG")
    plt = _pyplot()
    drawing = Drawing(plt, scene, np.array([index]))
    drawing.update(index)
    try:
        with _atomic_named(out, overwrite) as tmp:
            drawing.fig.savefig(tmp, dpi=drawing.dpi)
    finally:
        plt.close(drawing.fig)
    return out


@contextlib.contextmanager
def _atomic_named(out: Path, overwrite: bool) -> Any:
    """A temporary file next to ``out`` with ``out``'s suffix (the writers pick the format by
    it), renamed into place on success."""
    with atomic_path(out, overwrite) as tmp:
        named = tmp.with_name(tmp.name + out.suffix)
        try:
            yield named
            os.replace(named, tmp)
        finally:
            with contextlib.suppress(OSError):
                os.unlink(named)


def _nice(v: float) -> float:
    """The 1-2-5 number at or below v."""
    e = 10.0 ** np.floor(np.log10(v))
    return float(max(m for m in (1.0, 2.0, 5.0, 10.0) if m * e <= v * (1 + 1e-12)) * e)


class Drawing:
    """The figure of a scene and its update to stored instant k (``update(k)``)."""

    dpi = 80

    def __init__(self, plt: Any, scene: Scene, frames: np.ndarray):
        self.plt, self.scene = plt, scene
        self.structure = scene.kind == "structure"
        self.scale = self._magnification() if self.structure else 1.0
        every = np.concatenate([self._positions(p, k).reshape(-1, 3) for p in range(len(scene.parts))
                                for k in frames])
        every = every[np.all(np.isfinite(every), axis=1)] if len(every) else np.zeros((1, 3))
        lo, hi = every.min(axis=0), every.max(axis=0)
        size = float(np.max(hi - lo)) or 1.0
        self.flat = (hi[2] - lo[2]) <= 1e-9 * size
        tall = not self.flat and (hi[2] - lo[2]) > 1.5 * max(hi[0] - lo[0], hi[1] - lo[1])
        self.fig = plt.figure(figsize=(5.2, 6.4) if tall else (6.4, 4.8))
        self.ax = self.fig.add_subplot(111) if self.flat else self.fig.add_subplot(111, projection="3d")
        pad = 0.05 * size
        self._limits(lo - pad, hi + pad)
        self.artists: list[tuple[int, Any, str]] = []
        self._setup(int(frames[0]))
        kind = f"displacements x {self.scale:g}" if self.structure and self.scale != 1 else ""
        self.fig.suptitle(f"{scene.case_name}{' (' + scene.label + ')' if scene.label else ''}"
                          f"{', ' + kind if kind else ''}", fontsize=10)
        self.clock = self.fig.text(0.03, 0.03, "", fontsize=11)

    # geometry -------------------------------------------------------------------------
    def _magnification(self) -> float:
        """A 1-2-5 factor that shows the largest displacement at about 5 % of the model size
        (1 when it is that large already)."""
        part = self.scene.parts[0]
        X = part.points[0]
        size = float(np.max(X.max(axis=0) - X.min(axis=0))) or 1.0
        u = float(np.max(np.linalg.norm(part.point_data["displacement"], axis=2))) if len(X) else 0.0
        return 1.0 if u <= 0 or u >= 0.05 * size else _nice(0.05 * size / u)

    def _positions(self, p: int, k: int) -> np.ndarray:
        part = self.scene.parts[p]
        if self.structure:
            return part.points[k] + self.scale * part.point_data["displacement"][k]
        return part.points[k]

    def _limits(self, lo: np.ndarray, hi: np.ndarray) -> None:
        ax = self.ax
        if self.flat:
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
        else:      # true proportions (a tall tower fills the height), no axis thinner than 1/6
            span = np.maximum(hi - lo, float(np.max(hi - lo)) / 6)
            mid = (lo + hi) / 2
            ax.set_xlim(mid[0] - span[0] / 2, mid[0] + span[0] / 2)
            ax.set_ylim(mid[1] - span[1] / 2, mid[1] + span[1] / 2)
            ax.set_zlim(mid[2] - span[2] / 2, mid[2] + span[2] / 2)
            ax.set_box_aspect(tuple(span / span.max()), zoom=1.2)
            for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
                axis.set_major_locator(self.plt.MaxNLocator(3))
            ax.set_zlabel("z")
        ax.set_xlabel("x")
        ax.set_ylabel("y")

    def _segments(self, p: int, k: int) -> np.ndarray:
        """(L, 2, 2|3) line segments of part p at instant k."""
        xyz = self._positions(p, k)[self.scene.parts[p].lines]
        return xyz[..., :2] if self.flat else xyz

    def _lines(self, p: int, k: int, **style: Any) -> Any:
        """A line collection of part p, drawn at instant k."""
        if self.flat:
            from matplotlib.collections import LineCollection
            coll = LineCollection(list(self._segments(p, k)), **style)
            self.ax.add_collection(coll)
        else:
            from mpl_toolkits.mplot3d.art3d import Line3DCollection
            coll = Line3DCollection(list(self._segments(p, k)), **style)
            self.ax.add_collection3d(coll, autolim=False)
        return coll

    # artists --------------------------------------------------------------------------
    def _setup(self, k: int) -> None:
        if self.structure:
            data = self.scene.parts[0].cell_data
            name = "stress_ratio" if "stress_ratio" in data else "stress"
            v = data[name][np.isfinite(data[name])]
            from matplotlib.colors import Normalize
            if name == "stress_ratio":
                norm, cmap = Normalize(0.0, max(1.0, float(v.max()) if v.size else 1.0)), "turbo"
            else:
                a = float(np.abs(v).max()) if v.size else 1.0
                norm, cmap = Normalize(-a, a), "coolwarm"
            coll = self._lines(0, k, cmap=cmap, norm=norm, linewidths=2.0)
            self.artists.append((0, coll, name))
            label = "stress ratio max(σ/σ_t, −σ/σ_c)" if name == "stress_ratio" else "axial stress"
            self.fig.colorbar(coll, ax=self.ax, shrink=0.8, label=label)
            return
        styles = {"bodies": dict(colors="tab:blue", linewidths=3.0),
                  "cylinders": dict(colors="tab:red", linewidths=5.0),
                  "springs": dict(colors="tab:green", linewidths=1.5)}
        for p, part in enumerate(self.scene.parts):
            if part.name in styles and len(part.lines):
                self.artists.append((p, self._lines(p, k, **styles[part.name]), "lines"))
            if len(part.vertices):
                marker = dict(marker="o", s=30, facecolors="white", edgecolors="black", zorder=3) \
                    if part.name == "joints" else dict(marker="^", s=40, color="black", zorder=3)
                pts = part.points[0][part.vertices]
                sc = self.ax.scatter(pts[:, 0], pts[:, 1], **marker) if self.flat else \
                    self.ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], **marker)
                self.artists.append((p, sc, "points"))

    def update(self, k: int) -> list[Any]:
        """Draw stored instant k; returns the changed artists."""
        for p, artist, what in self.artists:
            part = self.scene.parts[p]
            if what == "points":
                xyz = self._positions(p, k)[part.vertices]
                if self.flat:
                    artist.set_offsets(xyz[:, :2])
                else:
                    artist._offsets3d = (xyz[:, 0], xyz[:, 1], xyz[:, 2])
                continue
            artist.set_segments(self._segments(p, k))
            if what != "lines":
                artist.set_array(np.nan_to_num(part.cell_data[what][k][:len(part.lines)]))
        self.clock.set_text(f"t = {self.scene.time[k]:.4g} s")
        return [a for _, a, _ in self.artists] + [self.clock]
