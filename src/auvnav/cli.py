"""The ``auvnav`` command: thin wrappers around library functions.

Each subcommand loads its inputs, calls one library function, prints a summary (or JSON with
``--json``) and saves products. :func:`main` is the one launcher: a known error (``AuvnavError``,
a missing file) becomes one line on stderr and exit code 1; a usage error exits 2; anything else is a
bug and keeps its traceback. Commands signal failure by raising, never by returning a code.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from auvnav.errors import AuvnavError, DiveFormatError

app = typer.Typer(
    name="auvnav",
    help="Consistent navigation, compass and depth repair, and 3D reconstructions for survey AUVs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# Options every command shares (DESIGN section 7).
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the machine-readable summary.")]
VerboseOpt = Annotated[int, typer.Option("-v", "--verbose", count=True, help="More log output.")]
QuietOpt = Annotated[bool, typer.Option("-q", "--quiet", help="Only warnings and errors.")]
OverwriteOpt = Annotated[bool, typer.Option("--overwrite", help="Replace existing outputs.")]
DiveArg = Annotated[Path, typer.Argument(help="A dive folder (format auvnav-dive/1).")]

log = logging.getLogger("auvnav")


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


def setup_logging(verbose: int = 0, quiet: bool = False) -> None:
    """Log to stderr: warnings always, info by default, debug with -v."""
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True)


def emit(summary: dict[str, Any], human: str, *, as_json: bool) -> None:
    """Print a command's result: JSON (``--json``) or the human summary."""
    if as_json:
        typer.echo(json.dumps(summary, indent=2, default=float))
    else:
        typer.echo(human)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (0 ok, 1 known error, 2 usage)."""
    try:
        app(args=argv, prog_name="auvnav")
    except SystemExit as exit_:
        code = exit_.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except AuvnavError as err:
        for line in str(err).splitlines() or [type(err).__name__]:
            typer.echo(f"auvnav: error: {line}", err=True)
        return 1
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError) as err:
        typer.echo(f"auvnav: error: {err.filename}: {err.strerror}", err=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())


# ---------------------------------------------------------------------------------------------
# validate
# ---------------------------------------------------------------------------------------------


@app.command()
def validate(
    dive: DiveArg,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Check a dive folder: every problem with its file, row and column; a summary when it is valid."""
    from auvnav.dive import validate_dive

    setup_logging(verbose, quiet)
    report = validate_dive(dive)
    for w in report.warnings:
        log.warning(w)
    if not report.ok:
        raise DiveFormatError(report.problems)
    valid_dive = report.dive
    if valid_dive is None:  # cannot happen: a report without problems carries its dive
        raise RuntimeError("validate_dive returned no dive and no problems")
    t0, t1 = valid_dive.time_span_s()
    summary = {
        "dive": str(dive),
        "valid": True,
        "duration_s": t1 - t0,
        "streams": {
            s.name: {
                "file": s.file,
                "rows": s.rows,
                "rate_hz": s.rate_hz,
                "gaps": [{"start_s": a, "length_s": b} for a, b in s.gaps],
            }
            for s in report.streams
        },
        "warnings": report.warnings,
    }
    lines = [f"{dive}: valid dive '{valid_dive.info.name}', {(t1 - t0) / 3600:.2f} h"]
    for s in report.streams:
        gaps = f", {len(s.gaps)} gap(s), longest {max(g[1] for g in s.gaps):.1f} s" if s.gaps else ""
        lines.append(f"  {s.name:<13} {s.file:<24} {s.rows:>8} rows  {s.rate_hz:7.2f} Hz{gaps}")
    emit(summary, "\n".join(lines), as_json=as_json)
