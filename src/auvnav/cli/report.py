"""``auvnav report DIVE|CAMPAIGN``: a dive's report stage, or the page of a campaign of dives."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from auvnav.cli.common import AllowOutsideOpt, JsonOpt, QuietOpt, VerboseOpt, app, emit, setup_logging


@app.command("report")
def report(
    folder: Annotated[
        Path,
        typer.Argument(
            metavar="DIVE|CAMPAIGN",
            help="A dive folder, or a folder of dive folders (as auvnav demo writes them).",
        ),
    ],
    allow_outside: AllowOutsideOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """The paper's figures and one self-contained HTML page (no network) from the products:
    DIVE/products/report/index.html, or CAMPAIGN/products/report/index.html with every dive (each
    dive's own report is brought up to date first)."""
    from auvnav.pipeline import BY_NAME, process, run_stage
    from auvnav.report.campaign import build_campaign_report, campaign_dives, format_campaign, is_campaign

    setup_logging(verbose, quiet)
    if is_campaign(folder):
        for dive in campaign_dives(folder):
            process(dive, only=["report"], allow_outside=allow_outside)
        result = build_campaign_report(folder)
        emit(result, format_campaign(result), as_json=as_json)
        return
    summary = run_stage(folder, "report", allow_outside=allow_outside)
    emit(summary, BY_NAME["report"].describe(summary), as_json=as_json)
