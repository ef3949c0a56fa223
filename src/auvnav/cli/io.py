"""``auvnav import`` and ``auvnav export``: a vehicle's logs in, a dive's products out."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from auvnav.cli.common import (
    DiveArg,
    JsonOpt,
    OverwriteOpt,
    QuietOpt,
    VerboseOpt,
    app,
    emit,
    log,
    setup_logging,
)
from auvnav.io.registry import EXPORTERS, IMPORTERS

ImportFormat = Enum("ImportFormat", {name: name for name in IMPORTERS}, type=str)  # type: ignore[misc]
ExportFormat = Enum("ExportFormat", {name: name for name in EXPORTERS}, type=str)  # type: ignore[misc]


class TrackSource(str, Enum):
    auto = "auto"
    slam = "slam"
    filter = "filter"
    dr = "dr"


def _formats(table: dict) -> str:
    return "; ".join(f"{name}: {info.title}" for name, info in table.items())


@app.command(
    "import",
    help="Read a vehicle's logs into a dive folder. FORMAT is one of: " + _formats(IMPORTERS) + ".",
)
def import_command(
    fmt: Annotated[ImportFormat, typer.Argument(metavar="FORMAT", help="The logs' format.")],  # type: ignore[valid-type]
    sources: Annotated[
        list[Path],
        typer.Argument(metavar="SOURCE...", help="Log files (or ROS 2 bag folders), in time order."),
    ],
    out: Annotated[Path, typer.Option("--out", help="The dive folder to write.")],
    config: Annotated[
        Path | None,
        typer.Option(
            "--config",
            help="Settings YAML: origin, heading_reference, topics, columns... (csv: the mapping).",
        ),
    ] = None,
    base: Annotated[
        Path | None,
        typer.Option(
            "--base", help="A dive folder whose streams, vehicle and metadata fill in what the logs lack."
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    from auvnav.io.api import import_dive
    from auvnav.io.common import format_summary

    setup_logging(verbose, quiet)
    summary = import_dive(fmt.value, sources, out, config=config, base=base, overwrite=overwrite)
    for w in summary.get("warnings", []):
        log.warning(f"{out}/{w}")
    emit(summary, format_summary(summary), as_json=as_json)


@app.command(
    "export",
    help="Write a dive's products for other tools. FORMAT is one of: " + _formats(EXPORTERS) + ".",
)
def export_command(
    dive: DiveArg,
    fmt: Annotated[ExportFormat, typer.Argument(metavar="FORMAT", help="The format to write.")],  # type: ignore[valid-type]
    out: Annotated[
        Path | None, typer.Option("--out", help="The file to write [DIVE/exports/<the format's file name>].")
    ] = None,
    source: Annotated[
        TrackSource,
        typer.Option(
            "--source", help="The trajectory: SLAM's, the filter's or dead reckoning [best there is]."
        ),
    ] = TrackSource.auto,
    sigma_m: Annotated[
        float | None,
        typer.Option(
            "--sigma-m",
            min=0.0,
            help="Position accuracy to write for a trajectory without one (dead reckoning).",
        ),
    ] = None,
    correction: Annotated[
        Path | None,
        typer.Option(
            "--correction", help="compass-table: this correction file [the dive's compass product]."
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    from auvnav.io.api import ExportOptions, export_dive

    setup_logging(verbose, quiet)
    options = ExportOptions(source=source.value, sigma_m=sigma_m, correction=correction)
    summary = export_dive(dive, fmt.value, out, options=options, overwrite=overwrite)
    details = ", ".join(f"{k} {v}" for k, v in summary.items() if k not in ("format", "dive", "out"))
    emit(summary, f"{summary['out']}: {summary['format']} ({details})", as_json=as_json)
