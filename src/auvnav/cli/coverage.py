"""``auvnav coverage``: the coverage stage of a dive, and the prediction of a survey's coverage before it.

``auvnav coverage DIVE [settings]`` runs the coverage stage (registered in :mod:`auvnav.cli.stages`
as the group's ``run`` command: the group takes a first argument that is not one of its commands as
a dive, so ``auvnav coverage DIVE`` is ``auvnav coverage run DIVE``); ``auvnav coverage predict
MISSION.yaml`` predicts spacing and gaps before the dive (:mod:`auvnav.coverage.predict`). A dive
folder called ``predict`` or ``run`` is given as ``./predict``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import click
import typer
from typer.core import TyperGroup

from auvnav.cli.common import JsonOpt, QuietOpt, VerboseOpt, app, emit, setup_logging
from auvnav.errors import ConfigError

#: The command ``auvnav coverage DIVE`` stands for.
DEFAULT_COMMAND = "run"


class DefaultCommandGroup(TyperGroup):
    """A group whose first argument, when it names none of its commands, goes to :data:`DEFAULT_COMMAND`."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        help_names = set(self.get_help_option_names(ctx))
        if args and args[0] not in self.commands and args[0] not in help_names:
            args = [DEFAULT_COMMAND, *args]
        return super().parse_args(ctx, args)

    def format_usage(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        formatter.write_usage(ctx.command_path, "DIVE [OPTIONS] | predict MISSION.yaml [OPTIONS]")


coverage_app = typer.Typer(
    cls=DefaultCommandGroup,
    help=(
        "Coverage: 'auvnav coverage DIVE' measures where a dive's images fell (gaps, overlap, line "
        "spacing: 'accordion', 'figure 8'); 'auvnav coverage predict MISSION.yaml' predicts them "
        "before the dive."
    ),
    no_args_is_help=True,
)
app.add_typer(coverage_app, name="coverage")


@coverage_app.command()
def predict(
    mission_file: Annotated[
        Path, typer.Argument(metavar="MISSION.yaml", help="The survey's mission file (auvnav-mission/1).")
    ],
    compass_correction: Annotated[
        Path | None,
        typer.Option(
            "--compass-correction",
            help="Correction file the vehicle applies (auvnav-compass-correction/1); its covariance is its uncertainty.",
        ),
    ] = None,
    uncorrected: Annotated[
        bool,
        typer.Option(
            "--uncorrected",
            help="With --compass-correction: the vehicle flies without it; the file is its deviation as estimated.",
        ),
    ] = False,
    deviation_peak_deg: Annotated[
        float | None,
        typer.Option(
            "--deviation-peak-deg",
            min=0.0,
            help="No correction: a one-cycle deviation of this peak, degrees, phase unknown (0: no deviation).",
        ),
    ] = None,
    vehicle_file: Annotated[
        Path | None,
        typer.Option(
            "--vehicle", help="vehicle.yaml with the stereo rig: the footprint at the mission's altitude."
        ),
    ] = None,
    footprint_width_m: Annotated[
        float | None,
        typer.Option(
            "--footprint-width-m", help="Without --vehicle: the footprint's width across track, metres."
        ),
    ] = None,
    declination_deg: Annotated[
        float, typer.Option("--declination-deg", help="Magnetic declination at the site, degrees east.")
    ] = 0.0,
    gap_width_m: Annotated[
        float,
        typer.Option(
            "--gap-width-m",
            min=0.0,
            help="A gap counts when at least this wide, metres (holes that relief leaves, not modelled, "
            "can be wider: see 'not modelled').",
        ),
    ] = 0.5,
    draws: Annotated[int, typer.Option("--draws", min=1, help="Monte Carlo draws.")] = 500,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the draws.")] = 0,
    cell_m: Annotated[float, typer.Option("--cell-m", min=0.005, help="Grid cell, metres.")] = 0.05,
    tolerance_m: Annotated[
        float,
        typer.Option("--tolerance-m", min=0.0, help="A pair is on plan within this of the plan, metres."),
    ] = 0.1,
    line_margin_m: Annotated[
        float,
        typer.Option("--line-margin-m", min=0.0, help="Spacing left out at each end of a line, metres."),
    ] = 10.0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Also write the prediction (JSON, every pair) to this file.")
    ] = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Before the dive: line spacing, gaps and coverage of a survey flown on the compass (Monte Carlo)."""
    from auvnav.compass.correction import read_correction
    from auvnav.coverage.plan import survey_plan
    from auvnav.coverage.predict import FootprintExtent, HeadingErrorPrior, format_prediction, predict_survey
    from auvnav.plan.missions import read_mission
    from auvnav.streams import write_json
    from auvnav.vehicle import read_vehicle

    setup_logging(verbose, quiet)
    if (compass_correction is None) == (deviation_peak_deg is None):
        raise typer.BadParameter(
            "give either --compass-correction FILE or --deviation-peak-deg X",
            param_hint="--compass-correction",
        )
    if uncorrected and compass_correction is None:
        raise typer.BadParameter("--uncorrected goes with --compass-correction", param_hint="--uncorrected")
    if (vehicle_file is None) == (footprint_width_m is None):
        raise typer.BadParameter(
            "give either --vehicle FILE or --footprint-width-m W", param_hint="--vehicle"
        )
    mission = read_mission(mission_file)
    plan = survey_plan(mission)
    if compass_correction is not None:
        prior = HeadingErrorPrior.from_correction(
            read_correction(compass_correction), applied=not uncorrected, source=str(compass_correction)
        )
    else:
        assert deviation_peak_deg is not None
        prior = HeadingErrorPrior.deviation_peak(
            math.radians(deviation_peak_deg), source="--deviation-peak-deg"
        )
    if vehicle_file is not None:
        footprint = FootprintExtent.of_vehicle(read_vehicle(vehicle_file), mission.altitude_m)
    else:
        assert footprint_width_m is not None
        footprint = FootprintExtent.of_width(footprint_width_m)
    if prior.kind == "corrected" and prior.covariance_rad2 is None:
        typer.echo(
            f"auvnav: warning: {compass_correction}: no covariance: the correction is taken as exact",
            err=True,
        )
    prediction = predict_survey(
        plan,
        prior,
        footprint,
        declination_rad=math.radians(declination_deg),
        draws=draws,
        seed=seed,
        cell_m=cell_m,
        gap_width_m=gap_width_m,
        margin_m=line_margin_m,
        tolerance_m=tolerance_m,
    )
    summary: dict[str, Any] = {"mission": str(mission_file), **prediction.summary()}
    if out is not None:
        if out.suffix.lower() != ".json":
            raise ConfigError(f"{out}: the prediction is written as JSON (.json)")
        write_json(summary, out)
    human = (
        f"mission {mission_file}: {len(plan.lines)} lines, {len(plan.pairs)} adjacent pairs\n"
        + format_prediction(summary)
    )
    emit(summary, human, as_json=as_json)
