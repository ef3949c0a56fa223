"""The ``auvnav`` command: thin commands grouped by domain, each around a library function.

Each command loads its inputs, calls one library function, prints a summary (or JSON with
``--json``) and saves products; a pipeline stage's command is built from the stage's settings
(:func:`auvnav.cli.common.stage_command`). :func:`main` is the one launcher: a known error
(``AuvnavError``, a missing file) becomes one line on stderr and exit code 1; a usage error exits 2;
an interrupt (Ctrl-C, SIGTERM) exits 130 or 143 after removing what was half-written; anything else
is a bug and keeps its traceback. Commands signal failure by raising, never by returning a code.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType
from typing import Annotated

import typer

from auvnav.cli import campaign, compass, coverage, dive, graph, io, sim, stages  # noqa: F401 (each registers its commands)
from auvnav.cli.common import app
from auvnav.errors import AuvnavError


def _print_version(value: bool) -> None:
    if value:
        from auvnav import __version__

        typer.echo(f"auvnav {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_print_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Consistent navigation, compass and depth repair, and 3D reconstructions for survey AUVs."""


def _terminated(signum: int, frame: FrameType | None) -> None:
    """SIGTERM as an exception, so that what a command was writing is removed on the way out."""
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (0 ok, 1 known error, 2 usage, 130/143 interrupted)."""
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        app(args=argv, prog_name="auvnav")
    except SystemExit as exit_:
        code = exit_.code
        if code == 128 + signal.SIGTERM:
            typer.echo("auvnav: terminated", err=True)
        return code if isinstance(code, int) else (0 if code is None else 1)
    except KeyboardInterrupt:
        typer.echo("auvnav: interrupted", err=True)
        return 130
    except AuvnavError as err:
        for line in str(err).splitlines() or [type(err).__name__]:
            typer.echo(f"auvnav: error: {line}", err=True)
        return 1
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as err:
        typer.echo(f"auvnav: error: {err.filename}: {err.strerror}", err=True)
        return 1
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


__all__ = ["app", "main"]


if __name__ == "__main__":
    sys.exit(main())
