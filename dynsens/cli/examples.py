"""``dynsens examples DIR``: copy the shipped example cases into a folder to start from."""
from __future__ import annotations

import click

from ..io.examples import copy_examples
from .main import cli
from .options import overwrite_option, verbosity_options


@cli.command()
@click.argument("folder", metavar="DIR", type=click.Path(path_type=str))
@overwrite_option
@verbosity_options
def examples(folder: str, overwrite: bool) -> None:
    """Copy the example cases shipped with dynsens (cases/*.yaml and the files they use) into DIR.

    DIR is made if missing; files that exist there are replaced only with --overwrite.
    """
    written = copy_examples(folder, overwrite=overwrite)
    cases = [p for p in written if p.suffix == ".yaml" and p.parent == written[0].parent]
    click.echo(f"copied {len(written)} files ({len(cases)} cases) to {folder}")
    sdof = next((p for p in written if p.name == "sdof_step.yaml"), None)
    if sdof is not None:
        click.echo(f"try: dynsens simulate {sdof}")
