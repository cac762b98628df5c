"""``--vtk DIR`` and ``--animate FILE`` (on ``simulate`` and ``export``), and ``dynsens export``."""
from __future__ import annotations

from pathlib import Path

import click

from .main import cli
from .options import compose, overwrite_option, verbosity_options

#: the state histories a drawing reads (velocities, joint reactions and cylinder pressures included)
DRAWN_HISTORIES = ("q", "qd", "lam", "p")

view_options = compose(
    click.option("--vtk", "vtk", type=click.Path(file_okay=False), default=None, metavar="DIR",
                 help="Write a ParaView time series (DIR/<name>.pvd and its VTU files) of the run "
                      "(pip install 'dynsens[vtk]')."),
    click.option("--vtk-every", "vtk_every", type=click.IntRange(min=1), default=1, show_default=True,
                 metavar="N", help="With --vtk: write every N-th stored instant (and the last)."),
    click.option("--animate", "animation", type=click.Path(dir_okay=False), default=None, metavar="FILE",
                 help="Write an animation of the run, FILE.gif (Pillow) or FILE.mp4 (needs ffmpeg); "
                      "at most 200 frames."))


def check_views(result_file: str | Path, labels: list[str], vtk: str | None, animation: str | None,
                overwrite: bool) -> None:
    """Refuse, before any work, outputs that exist (without ``overwrite``), cannot be written, or
    need a missing package; ``labels``: the runs of the result file (``[""]`` for a simulation)."""
    if vtk:
        from ..io.paths import check_output_folder
        from ..io.vtk import need_meshio, vtk_targets
        need_meshio()
        check_output_folder(vtk, vtk_targets(result_file, vtk, labels), overwrite, option="--vtk")
    if animation:
        from ..animate import check_animation_path
        check_animation_path(animation, overwrite)


def write_views(result_file: str | Path, vtk: str | None, animation: str | None, overwrite: bool,
                vtk_every: int = 1) -> None:
    """Write the requested views of ``result_file`` and say where they are."""
    if vtk:
        from ..io.vtk import export_vtk
        for p in export_vtk(result_file, vtk, overwrite, vtk_every):
            click.echo(f"ParaView: {p}")
    if animation:
        from ..animate import animate
        click.echo(f"animation: {animate(result_file, animation, overwrite)}")


@cli.command()
@click.argument("result_file", type=click.Path(dir_okay=False, path_type=str))
@view_options
@overwrite_option
@verbosity_options
def export(result_file: str, vtk: str | None, vtk_every: int, animation: str | None, overwrite: bool) -> None:
    """Export RESULT_FILE (of simulate, or of optimize: its start and optimum) for ParaView
    (--vtk DIR) or as an animation (--animate FILE.gif|.mp4)."""
    from ..errors import DynsensError
    from ..io.scene import stored_runs
    if not vtk and not animation:
        raise DynsensError("export: expected --vtk DIR and/or --animate FILE, found neither")
    check_views(result_file, list(stored_runs(result_file)), vtk, animation, overwrite)
    write_views(result_file, vtk, animation, overwrite, vtk_every)
