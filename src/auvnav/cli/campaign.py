"""``auvnav campaign DIVE... --out CAMPAIGN``: several dives in one frame (:mod:`auvnav.campaign`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from auvnav.cli.common import (
    JsonOpt,
    OverwriteOpt,
    QuietOpt,
    SchedulerOpt,
    VerboseOpt,
    WorkersOpt,
    app,
    emit,
    setup_logging,
)
from auvnav.errors import ConfigError


def format_campaign(summary: dict[str, Any]) -> str:
    lines = [
        f"campaign of {len(summary['dives'])} dives ({', '.join(summary['dives'])}), registration {summary['registration']}"
    ]
    for pair in summary["inter_dive"]:
        a, b = pair["dives"]
        lines.append(
            f"{a} x {b}: {pair['candidates_tested']} candidates tested ({pair['seeds_verified']} seeds verified), "
            f"{pair['verified']} verified, {pair['kept']} kept"
        )
    joint = summary["joint_graph"]
    lines.append(
        f"joint graph: {joint['variables']} variables, {joint['factors']} factors, solved in {joint['solve_s']:.1f} s"
    )
    changes = summary["changes"]
    if changes["status"] == "done":
        lines.append(
            f"DEM difference {changes['dives'][1]} - {changes['dives'][0]}: {changes['changes']} changed regions"
        )
    else:
        lines.append(f"DEM difference: {changes['reason']}")
    return "\n".join(lines)


@app.command("campaign")
def campaign(
    dives: Annotated[
        list[Path],
        typer.Argument(metavar="DIVE...", help="Dive folders, each with its SLAM (products/slam/)."),
    ],
    out: Annotated[Path, typer.Option("--out", help="The campaign folder to write.")],
    truth_loops: Annotated[
        bool,
        typer.Option(
            "--truth-loops",
            help="Simulated dives without images: verify inter-dive candidates from the simulator's truth (a testing aid).",
        ),
    ] = False,
    false_loops: Annotated[
        float,
        typer.Option(
            "--false-loops",
            min=0.0,
            max=0.99,
            help="With --truth-loops: fraction of non-overlapping candidates that pass as false matches.",
        ),
    ] = 0.0,
    seed: Annotated[
        int, typer.Option("--seed", help="With --truth-loops: seed of the noise and the false matches.")
    ] = 0,
    overwrite: OverwriteOpt = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Several dives in one frame: inter-dive loop closures (the dives' images registered as the loop
    stage registers its own), one joint graph, per-dive trajectories in the common frame, the DEM
    difference where two dives have a reconstruction."""
    from auvnav.campaign import ImageRegistration, run_campaign
    from auvnav.executor import make_executor

    setup_logging(verbose, quiet)
    if (false_loops or seed) and not truth_loops:
        raise ConfigError("--false-loops and --seed apply to --truth-loops only")
    with make_executor(scheduler, workers) as executor:
        if truth_loops:
            from auvnav.sim.repeat import TruthRegistration

            register: Any = TruthRegistration(list(dives), false_fraction=false_loops, seed=seed)
            name = f"truth (simulator; {false_loops:g} false)"
        else:
            register = ImageRegistration(list(dives), executor=executor)
            name = "images"
        summary = run_campaign(list(dives), out, register, overwrite=overwrite, registration_name=name)
    emit(summary, format_campaign(summary), as_json=as_json)
