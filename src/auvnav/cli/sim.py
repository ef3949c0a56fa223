"""``auvnav plan``, ``auvnav simulate`` and ``auvnav demo``: missions, the simulator, the paper's experiment."""

from __future__ import annotations

from enum import Enum
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
    progress_bars,
    setup_logging,
)

plan_app = typer.Typer(help="Write mission files (format auvnav-mission/1).", no_args_is_help=True)
app.add_typer(plan_app, name="plan")

OutMissionOpt = Annotated[Path, typer.Option("--out", help="The mission file to write (YAML).")]
HeadingsOpt = Annotated[int | None, typer.Option("--headings", help="navcheck: arms of the star [12].")]
LegOpt = Annotated[
    float | None, typer.Option("--leg-m", help="navcheck: arm length [50]; transit: leg length [2000], m.")
]
GridOpt = Annotated[float | None, typer.Option("--grid-m", help="navcheck: side of the grid [10], m.")]
GridSpacingOpt = Annotated[
    float | None, typer.Option("--grid-spacing-m", help="navcheck: grid line spacing [1], m.")
]
WidthOpt = Annotated[float | None, typer.Option("--width-m", help="survey: line length [75], m.")]
HeightOpt = Annotated[float | None, typer.Option("--height-m", help="survey: extent across lines [50], m.")]
SpacingOpt = Annotated[float | None, typer.Option("--spacing-m", help="survey: line spacing [1], m.")]
LeadInOpt = Annotated[float | None, typer.Option("--lead-in-m", help="survey: lead-in leg [100], m.")]
LegsOpt = Annotated[int | None, typer.Option("--legs", help="transit: number of legs [4].")]
TurnsOpt = Annotated[float | None, typer.Option("--turns", help="spin: full turns [3].")]


def _plan(kind: str, options: dict[str, Any], out: Path, overwrite: bool, as_json: bool) -> None:
    from auvnav.errors import OutputExistsError
    from auvnav.plan.missions import build_mission, write_mission

    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    mission = build_mission(kind, options)
    write_mission(mission, out)
    summary = {"mission": str(out), **mission.summary()}
    human = (
        f"{out}: {kind} mission, {summary['legs']} legs, {summary['line_length_m']:.0f} m of lines "
        f"at {mission.speed_mps:g} m/s, {mission.altitude_m:g} m altitude"
    )
    emit(summary, human, as_json=as_json)


@plan_app.command("navcheck")
def plan_navcheck(
    out: OutMissionOpt,
    headings: HeadingsOpt = None,
    leg_m: LegOpt = None,
    grid_m: GridOpt = None,
    grid_spacing_m: GridSpacingOpt = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Navigation check dive: reciprocal legs on a star of headings plus a grid over the centre."""
    options = {"headings": headings, "leg_m": leg_m, "grid_m": grid_m, "grid_spacing_m": grid_spacing_m}
    _plan("navcheck", options, out, overwrite, as_json)


@plan_app.command("survey")
def plan_survey(
    out: OutMissionOpt,
    width_m: WidthOpt = None,
    height_m: HeightOpt = None,
    spacing_m: SpacingOpt = None,
    lead_in_m: LeadInOpt = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Full-coverage lawnmower after a lead-in leg."""
    options = {"width_m": width_m, "height_m": height_m, "spacing_m": spacing_m, "lead_in_m": lead_in_m}
    _plan("survey", options, out, overwrite, as_json)


@plan_app.command("transit")
def plan_transit(
    out: OutMissionOpt,
    legs: LegsOpt = None,
    leg_m: LegOpt = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Long straight sub-sea legs at evenly spaced headings, GPS fixes at the surface between them."""
    _plan("transit", {"legs": legs, "leg_m": leg_m}, out, overwrite, as_json)


@plan_app.command("spin")
def plan_spin(
    out: OutMissionOpt,
    turns: TurnsOpt = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Full turns on the spot at constant depth, for magnetometer calibration."""
    _plan("spin", {"turns": turns}, out, overwrite, as_json)


class _Switch(str, Enum):
    none = "none"
    default = "default"


class WaterOpt(str, Enum):
    clear = "clear"
    coastal = "coastal"
    turbid = "turbid"


@app.command()
def simulate(
    scenario: Annotated[
        str, typer.Argument(metavar="SCENARIO", help="navcheck | survey | transit | spin | MISSION.yaml")
    ],
    out: Annotated[Path, typer.Option("--out", help="The dive folder to write.")],
    seed: Annotated[
        int, typer.Option("--seed", help="The dive's seed: seafloor, noise, per-dive errors.")
    ] = 0,
    vehicle_seed: Annotated[
        int, typer.Option("--vehicle-seed", help="The vehicle's seed: its DVL mounting, shared across dives.")
    ] = 0,
    deviation: Annotated[
        _Switch, typer.Option("--deviation", help="Compass hard/soft-iron deviation.")
    ] = _Switch.default,
    tide: Annotated[_Switch, typer.Option("--tide", help="Tide in the pressure record.")] = _Switch.default,
    sensor_errors: Annotated[
        _Switch, typer.Option("--sensor-errors", help="'none': every sensor exact.")
    ] = _Switch.default,
    compass_correction: Annotated[
        Path | None,
        typer.Option("--compass-correction", help="Correction file the vehicle applies in real time."),
    ] = None,
    headings: HeadingsOpt = None,
    leg_m: LegOpt = None,
    grid_m: GridOpt = None,
    grid_spacing_m: GridSpacingOpt = None,
    width_m: WidthOpt = None,
    height_m: HeightOpt = None,
    spacing_m: SpacingOpt = None,
    lead_in_m: LeadInOpt = None,
    legs: LegsOpt = None,
    turns: TurnsOpt = None,
    duration_s: Annotated[
        float | None, typer.Option("--duration-s", help="Cut the dive after this much vehicle time, s.")
    ] = None,
    usbl: Annotated[bool, typer.Option("--usbl", help="Also simulate USBL fixes.")] = False,
    images: Annotated[
        bool, typer.Option("--images/--no-images", help="Render the stereo camera's images.")
    ] = True,
    image_scale: Annotated[
        float, typer.Option("--image-scale", help="Image size relative to 1360 x 1024.")
    ] = 1.0,
    image_rate_hz: Annotated[float, typer.Option("--image-rate-hz", help="Camera trigger rate, Hz.")] = 1.0,
    water: Annotated[
        WaterOpt,
        typer.Option(
            "--water",
            help="Water of the images: Jerlov type IB (clear), 3C (coastal) or 5C (turbid) attenuation, "
            "with scattering, backscatter and the camera's gain to match.",
        ),
    ] = WaterOpt.clear,
    raw_images: Annotated[
        bool,
        typer.Option(
            "--raw-images",
            help="Write the sensor's raw RGGB mosaics at 12 bits (16-bit PNG), as survey cameras do, "
            "instead of demosaiced colour images; vehicle.yaml names the filter.",
        ),
    ] = False,
    truth_loops: Annotated[
        bool,
        typer.Option("--truth-loops", help="Write truth/loops.csv: loop closures from the truth."),
    ] = False,
    false_loops: Annotated[
        float,
        typer.Option("--false-loops", min=0.0, max=0.99, help="Fraction of truth loops that are false."),
    ] = 0.0,
    repeat_of: Annotated[
        Path | None,
        typer.Option(
            "--repeat-of",
            metavar="DIVE",
            help="A repeat survey: fly SCENARIO (give the first dive's scenario and geometry options) over "
            "the seafloor of the simulated DIVE days later, with its own --seed (noise, GPS fixes, DVL "
            "errors), the tallest coral head of DIVE's imaged area removed (truth/change.yaml).",
        ),
    ] = None,
    days_later: Annotated[
        float, typer.Option("--days-later", min=0.0, help="With --repeat-of: days after DIVE (another tide).")
    ] = 3.0,
    keep_coral: Annotated[
        bool, typer.Option("--keep-coral", help="With --repeat-of: remove no coral head (no change).")
    ] = False,
    overwrite: OverwriteOpt = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Simulate a dive (vehicle, guidance on its own navigation, sensors) into a dive folder with truth/."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from auvnav.sim.run import run_scenario

    setup_logging(verbose, quiet)
    simulate_fn: Any = run_scenario
    if repeat_of is not None:
        simulate_fn = _repeat_simulator(repeat_of, seed, days_later, keep_coral)
    elif days_later != 3.0 or keep_coral:
        raise typer.BadParameter("--days-later and --keep-coral apply to --repeat-of only")
    geometry = {
        "headings": headings,
        "leg_m": leg_m,
        "grid_m": grid_m,
        "grid_spacing_m": grid_spacing_m,
        "width_m": width_m,
        "height_m": height_m,
        "spacing_m": spacing_m,
        "lead_in_m": lead_in_m,
        "legs": legs,
        "turns": turns,
    }
    options = {
        "seed": seed,
        "vehicle_seed": vehicle_seed,
        "deviation": deviation.value,
        "tide": tide.value,
        "sensor_errors": sensor_errors.value,
        "compass_correction": compass_correction,
        "geometry": geometry,
        "max_duration_s": duration_s,
        "usbl": usbl,
        "overwrite": overwrite,
        "truth_loops": truth_loops,
        "false_loops": false_loops,
        "image_rate_hz": image_rate_hz,
    }
    if as_json or quiet:
        summary = simulate_fn(scenario, out, **options)
    else:
        columns = (
            TextColumn("simulating"),
            BarColumn(),
            TextColumn("{task.description}"),
            TimeElapsedColumn(),
        )
        with Progress(*columns, transient=True) as bar:
            task = bar.add_task("", total=1.0)

            def progress(elapsed_s: float, expected_s: float) -> None:
                done = min(elapsed_s / expected_s, 1.0)
                bar.update(task, completed=done, description=f"{elapsed_s / 3600:.2f} h of vehicle time")

            summary = simulate_fn(scenario, out, progress=progress, **options)
    if images:
        summary["images"] = _render_images(
            out,
            image_scale,
            image_rate_hz,
            seed,
            as_json or quiet,
            workers,
            scheduler,
            water.value,
            raw_images,
        )
    end = summary["end_error_m"]
    human = (
        f"{out}: {summary['mission']} dive, {summary['duration_s'] / 3600:.2f} h, "
        f"{summary['horizontal_distance_m']:.0f} m travelled"
        + ("" if end is None else f"; onboard minus true at the last surfacing {end:.2f} m")
        + ("" if summary["completed"] else " (cut before the mission's end)")
    )
    if truth_loops:
        n = summary["truth_loops"]
        human += f"\ntruth loops: {n['loops']} ({n['consecutive']} consecutive), {n['false']} false"
    if repeat_of is not None:
        removed = summary["change"].get("removed", [])
        human += (
            f"\nrepeat of {repeat_of} (site seed {summary['change']['site_seed']}), {days_later:g} days later"
            + (
                "; no coral head removed"
                if not removed
                else "; coral head removed at north {north_m:.1f} m, east {east_m:.1f} m: {height_m:.2f} m high, "
                "{area_m2:.2f} m^2 (truth/change.yaml)".format(**removed[0])
            )
        )
    emit(summary, human, as_json=as_json)


def _repeat_simulator(first: Path, seed: int, days_later: float, keep_coral: bool) -> Any:
    """``run_scenario`` for a repeat survey of the simulated dive ``first``
    (:func:`auvnav.sim.repeat.simulate_repeat`)."""
    from auvnav.config import load_yaml
    from auvnav.errors import ConfigError

    truth = first / "truth" / "truth.yaml"
    if not truth.is_file():
        raise ConfigError(f"{truth}: not found (--repeat-of needs a simulated dive)")
    data, problems = load_yaml(truth, str(truth))
    if problems or not isinstance(data, dict) or "seafloor" not in data:
        raise ConfigError(f"{truth}: not a simulated dive's truth (no seafloor)")
    if int(data.get("seed", -1)) == seed:
        raise ConfigError(f"--seed {seed} is {first}'s own: give the repeat survey another --seed")
    if not keep_coral and not (first / "images" / "index.csv").is_file():
        raise ConfigError(
            f"{first}: no images/index.csv (the coral head removed is one it imaged): give --keep-coral"
        )

    def run(scenario: str, out: Path, **options: Any) -> dict[str, Any]:
        from auvnav.sim.repeat import simulate_repeat

        options.pop("seed")
        return simulate_repeat(
            first,
            out,
            seed=seed,
            days_later=days_later,
            remove_coral=not keep_coral,
            scenario=scenario,
            **options,
        )

    return run


def _render_images(
    out: Path,
    scale: float,
    rate_hz: float,
    seed: int,
    silent: bool,
    workers: int | None,
    scheduler: str | None,
    water: str = "clear",
    raw: bool = False,
) -> int:
    """Render a simulated dive's stereo images (with a progress bar unless silent); the pair count."""
    from auvnav.executor import make_executor
    from auvnav.sim.camera import render_dive_images

    if not 0 < scale <= 4 or rate_hz <= 0:
        raise typer.BadParameter("--image-scale must be in (0, 4] and --image-rate-hz positive")
    with progress_bars(silent) as progress, make_executor(scheduler, workers) as executor:
        index = render_dive_images(
            out,
            scale=scale,
            rate_hz=rate_hz,
            seed=seed,
            water=water,  # type: ignore[arg-type]
            raw=raw,
            executor=executor,
            progress=None if progress is None else (lambda done, total: progress("rendering", done, total)),
        )
    return len(index)


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Folder for the campaign's dives.")] = Path(
        "demo-output"
    ),
    quick: Annotated[
        bool,
        typer.Option("--quick", help="Small geometry, quarter-scale images: about 4 minutes instead of 25."),
    ] = False,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """The paper's experiment on a built-in simulated campaign: every stage that exists, measured."""
    from auvnav.demo import format_demo, run_demo

    setup_logging(verbose, quiet)
    say = None if (as_json or quiet) else (lambda text: typer.echo(f"... {text}", err=True))
    summary = run_demo(out, quick=quick, overwrite=overwrite, progress=say)
    emit(summary, format_demo(summary), as_json=as_json)
