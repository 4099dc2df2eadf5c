"""The ``skyfix`` command: serve, db, solve, solve-image, sim, replay, calibrate, reprocess."""

from __future__ import annotations

from typing import Annotated

import typer

from client.cli import replay

from . import db
from .calibrate import calibrate_camera
from .reprocess import reprocess_recordings
from .serve import serve
from .sim import sim
from .solve import solve_frames
from .solve_image import solve_image_files

app = typer.Typer(help="skyfix: lost-in-space star identification.", no_args_is_help=True,
                  pretty_exceptions_enable=False)


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"skyfix {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                                help="Print the version and exit.")] = False) -> None:
    """skyfix: lost-in-space star identification."""
app.add_typer(db.app, name="db")
app.command("serve")(serve)
app.command("solve")(solve_frames)
app.command("sim")(sim)
app.command("solve-image")(solve_image_files)
app.command("replay")(replay)
app.command("calibrate")(calibrate_camera)
app.command("reprocess")(reprocess_recordings)


def main() -> None:
    """Console-script entry point: every mistake ends in one line and a non-zero exit."""
    import sys

    from .errors import run

    sys.exit(run(app))


__all__ = ["app", "main"]
