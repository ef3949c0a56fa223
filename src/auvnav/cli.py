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
from enum import Enum
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


# ---------------------------------------------------------------------------------------------
# compass
# ---------------------------------------------------------------------------------------------

compass_app = typer.Typer(
    help="Compass: declination, magnetometer calibration, deviation fit.", no_args_is_help=True
)
app.add_typer(compass_app, name="compass")


def _date2posix(text: str) -> float:
    """POSIX seconds (UTC) of an ISO date ``YYYY-MM-DD`` or a decimal year such as ``2025.5``."""
    import datetime as dt

    from auvnav.compass import decimal_year2posix

    try:
        if "-" in text.lstrip("-"):
            day = dt.date.fromisoformat(text)
            return dt.datetime(day.year, day.month, day.day, tzinfo=dt.timezone.utc).timestamp()
        return decimal_year2posix(float(text))
    except ValueError as err:
        raise typer.BadParameter(
            f"{text!r} is neither an ISO date (YYYY-MM-DD) nor a decimal year", param_hint="DATE"
        ) from err


@compass_app.command(context_settings={"ignore_unknown_options": True})  # negative LAT/LON
def declination(
    lat_deg: Annotated[float, typer.Argument(metavar="LAT_DEG", help="Geodetic latitude, degrees north.")],
    lon_deg: Annotated[float, typer.Argument(metavar="LON_DEG", help="Longitude, degrees east.")],
    date: Annotated[str, typer.Argument(metavar="DATE", help="ISO date YYYY-MM-DD (UTC) or decimal year.")],
    height_km: Annotated[
        float, typer.Option("--height-km", help="Height above the WGS84 ellipsoid, km.")
    ] = 0.0,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """The geomagnetic field at a place and date (WMM, or IGRF outside the WMM years)."""
    import math

    from auvnav.compass import earth_field, posix2decimal_year

    setup_logging(verbose, quiet)
    time_s = _date2posix(date)
    field = earth_field(math.radians(lat_deg), math.radians(lon_deg), time_s, height_m=1e3 * height_km)
    north, east, down = (field.b_ned_T * 1e9).tolist()
    d_deg, i_deg = math.degrees(field.declination_rad), math.degrees(field.inclination_rad)
    summary = {
        "latitude_deg": lat_deg,
        "longitude_deg": lon_deg,
        "height_km": height_km,
        "decimal_year": posix2decimal_year(time_s),
        "declination_deg": d_deg,
        "inclination_deg": i_deg,
        "north_nT": north,
        "east_nT": east,
        "down_nT": down,
        "horizontal_nT": field.horizontal_T * 1e9,
        "total_nT": field.total_T * 1e9,
        "model": field.model,
    }
    human = "\n".join(
        [
            f"{abs(lat_deg):.4f} {'N' if lat_deg >= 0 else 'S'}, {abs(lon_deg):.4f} "
            f"{'E' if lon_deg >= 0 else 'W'}, {height_km:g} km, {date} "
            f"({summary['decimal_year']:.3f}), {field.model}",
            f"  Declination  {abs(d_deg):9.2f} deg {'E' if d_deg >= 0 else 'W'}",
            f"  Inclination  {abs(i_deg):9.2f} deg {'down' if i_deg >= 0 else 'up'}",
            f"  North        {north:9.1f} nT",
            f"  East         {east:9.1f} nT",
            f"  Down         {down:9.1f} nT",
            f"  Horizontal   {summary['horizontal_nT']:9.1f} nT",
            f"  Total        {summary['total_nT']:9.1f} nT",
        ]
    )
    emit(summary, human, as_json=as_json)


@compass_app.command("fit")
def compass_fit(
    dives: Annotated[list[Path], typer.Argument(metavar="DIVE", help="Dive folders, pooled.")],
    reference: Annotated[
        str,
        typer.Option(
            "--reference",
            help="slam (products/slam/trajectory.csv), truth (a simulated dive's) or a trajectory file.",
        ),
    ] = "slam",
    transits: Annotated[
        list[Path] | None,
        typer.Option(
            "--transits",
            metavar="DIVE",
            help="A dive whose GPS course made good fixes the constant; repeat for more (a DIVE may be one).",
        ),
    ] = None,
    harmonics: Annotated[int, typer.Option("--harmonics", min=0, help="Harmonics of eq. 5.")] = 3,
    max_turn_rate_deg_s: Annotated[
        float | None,
        typer.Option("--max-turn-rate-deg-s", min=0.0, help="Pairs only while turning slower [2], deg/s."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", help="Correction file [DIVE/products/compass/correction.yaml]; a .png beside it."
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Fit the compass correction (eq. 5-6) against a reference heading; the constant from transits."""
    from auvnav.compass.fit import format_fit_summary
    from auvnav.report.compass_figures import run_compass_fit

    setup_logging(verbose, quiet)
    summary = run_compass_fit(
        dives,
        reference=reference,
        transits=transits or [],
        harmonics=harmonics,
        out=out,
        overwrite=overwrite,
        max_turn_rate_deg_s=max_turn_rate_deg_s,
    )
    emit(summary, format_fit_summary(summary), as_json=as_json)


class _CalibrationMethod(str, Enum):
    levelled = "levelled"
    ellipsoid = "ellipsoid"


@compass_app.command("calibrate")
def compass_calibrate(
    dive: DiveArg,
    method: Annotated[
        _CalibrationMethod,
        typer.Option("--method", help="levelled: horizontal fit (a barely tilting spin); ellipsoid: 3D."),
    ] = _CalibrationMethod.levelled,
    field_model: Annotated[
        bool,
        typer.Option(
            "--field-model/--no-field-model",
            help="Reference the vertical to the geomagnetic model's inclination at the dive's site and date.",
        ),
    ] = True,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Hard- and soft-iron calibration from the dive's raw magnetometer (a spin), with heading scores."""
    from auvnav.compass.calibrate import calibrate_dive, format_calibration

    setup_logging(verbose, quiet)
    summary = calibrate_dive(dive, method=method.value, field_model=field_model)
    emit(summary, format_calibration(summary), as_json=as_json)


# ---------------------------------------------------------------------------------------------
# navigate, evaluate
# ---------------------------------------------------------------------------------------------


@app.command()
def navigate(
    dive: DiveArg,
    compass_correction: Annotated[
        Path | None,
        typer.Option("--compass-correction", help="Compass correction file applied to the heading (eq. 5)."),
    ] = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Dead reckoning, filter and smoother; writes DIVE/products/nav/ (a rerun replaces it)."""
    from auvnav.nav.products import format_summary, run_navigation

    setup_logging(verbose, quiet)
    summary = run_navigation(dive, compass_correction=compass_correction)
    emit(summary, format_summary(summary), as_json=as_json)


@app.command()
def loops(
    dive: DiveArg,
    feature_scale: Annotated[
        float | None,
        typer.Option(
            "--feature-scale", help="Resize factor for SIFT (default: to 680 px wide, half of 1360)."
        ),
    ] = None,
    workers: Annotated[int | None, typer.Option("--workers", help="Processes (default: every core).")] = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Stereo features, loop-closure candidates from the navigation, verification; writes DIVE/products/vision/."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from auvnav.vision.features import FeatureSettings
    from auvnav.vision.loops import LoopSettings, format_loop_summary, run_loop_stage

    setup_logging(verbose, quiet)
    if feature_scale is not None and not 0 < feature_scale <= 1:
        raise typer.BadParameter("must be in (0, 1]", param_hint="--feature-scale")
    settings = LoopSettings(features=FeatureSettings(scale=feature_scale))
    if as_json or quiet:
        summary = run_loop_stage(dive, settings=settings, workers=workers)
    else:
        columns = (TextColumn("{task.description:9}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
        with Progress(*columns, transient=True) as bar:
            tasks: dict[str, Any] = {}

            def progress(stage: str, done: int, total: int) -> None:
                if stage not in tasks:
                    tasks[stage] = bar.add_task(stage, total=total)
                bar.update(tasks[stage], completed=done, total=total)

            summary = run_loop_stage(dive, settings=settings, workers=workers, progress=progress)
    emit(summary, format_loop_summary(summary), as_json=as_json)


@app.command()
def evaluate(
    dive: DiveArg,
    compass_correction: Annotated[
        Path | None,
        typer.Option("--compass-correction", help="Score this correction file against the true deviation."),
    ] = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Score a simulated dive's products against its truth (the products that exist)."""
    from auvnav.evaluate import evaluate_dive, format_scores

    setup_logging(verbose, quiet)
    result = evaluate_dive(dive, compass_correction=compass_correction)
    emit(result, format_scores(result), as_json=as_json)


# ---------------------------------------------------------------------------------------------
# depth
# ---------------------------------------------------------------------------------------------


@app.command()
def depth(
    dive: DiveArg,
    tide: Annotated[
        Path | None,
        typer.Option("--tide", help="Tide constituent file (name, amplitude_m, phase_deg) to correct with."),
    ] = None,
    atmospheric: Annotated[
        Path | None,
        typer.Option("--atmospheric", help="Atmospheric pressure series (t, pressure_dbar) [dive.yaml]."),
    ] = None,
    estimate_tide: Annotated[
        bool, typer.Option("--estimate-tide", help="Estimate the tide from the loop closures alone.")
    ] = False,
    loops: Annotated[
        Path | None,
        typer.Option("--loops", help="Loop-closure file [DIVE/products/vision/loops.csv]."),
    ] = None,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Check pressure depth against loop closures (paper Fig. 6); writes DIVE/products/depth/."""
    from auvnav.depth.validation import format_summary
    from auvnav.report.depth_figures import depth_products

    setup_logging(verbose, quiet)
    summary = depth_products(
        dive,
        tide_path=tide,
        atmospheric_path=atmospheric,
        loops_path=loops,
        estimate=estimate_tide,
        overwrite=overwrite,
    )
    emit(summary, format_summary(summary), as_json=as_json)


# ---------------------------------------------------------------------------------------------
# plan, simulate
# ---------------------------------------------------------------------------------------------

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
    truth_loops: Annotated[
        bool,
        typer.Option("--truth-loops", help="Write truth/loops.csv: loop closures from the truth."),
    ] = False,
    false_loops: Annotated[
        float,
        typer.Option("--false-loops", min=0.0, max=0.99, help="Fraction of truth loops that are false."),
    ] = 0.0,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Simulate a dive (vehicle, guidance on its own navigation, sensors) into a dive folder with truth/."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from auvnav.sim.run import run_scenario

    setup_logging(verbose, quiet)
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
        summary = run_scenario(scenario, out, **options)
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

            summary = run_scenario(scenario, out, progress=progress, **options)
    if images:
        summary["images"] = _render_images(out, image_scale, image_rate_hz, seed, as_json or quiet)
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
    emit(summary, human, as_json=as_json)


def _render_images(out: Path, scale: float, rate_hz: float, seed: int, silent: bool) -> int:
    """Render a simulated dive's stereo images (with a progress bar unless silent); the pair count."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from auvnav.sim.camera import render_dive_images

    if not 0 < scale <= 4 or rate_hz <= 0:
        raise typer.BadParameter("--image-scale must be in (0, 4] and --image-rate-hz positive")
    if silent:
        return len(render_dive_images(out, scale=scale, rate_hz=rate_hz, seed=seed))
    columns = (TextColumn("rendering"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, transient=True) as bar:
        task = bar.add_task("", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        return len(render_dive_images(out, scale=scale, rate_hz=rate_hz, seed=seed, progress=progress))


# ---------------------------------------------------------------------------------------------
# demo
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# graph
# ---------------------------------------------------------------------------------------------

graph_app = typer.Typer(
    help="Pose-graph files (g2o, TORO): optimise any 2D or 3D graph.", no_args_is_help=True
)
app.add_typer(graph_app, name="graph")


class _RobustKernel(str, Enum):
    none = "none"
    huber = "huber"
    cauchy = "cauchy"


class _InitialGuess(str, Enum):
    file = "file"
    chordal = "chordal"


@graph_app.command("optimize")
def graph_optimize(
    graph_file: Annotated[
        Path, typer.Argument(metavar="IN", help="A g2o or TORO pose-graph file, 2D or 3D.")
    ],
    out: Annotated[Path, typer.Option("--out", help="The optimised graph, g2o.")],
    robust: Annotated[
        _RobustKernel, typer.Option("--robust", help="Kernel on loop closures; lists those it rejects.")
    ] = _RobustKernel.none,
    initial: Annotated[
        _InitialGuess,
        typer.Option("--initial", help="Initial guess: the file's vertices or a chordal relaxation."),
    ] = _InitialGuess.file,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Optimise a pose graph (Levenberg-Marquardt); print its chi-square cost before and after."""
    from auvnav.slam.g2o import read_g2o, write_g2o
    from auvnav.slam.solve import optimize_batch
    from auvnav.streams import ensure_writable

    setup_logging(verbose, quiet)
    ensure_writable(out, overwrite=overwrite)
    result = optimize_batch(read_g2o(graph_file), robust=robust.value, initial=initial.value)
    write_g2o(result.graph, out, overwrite=overwrite)
    summary = {**result.summary(), "output": str(out)}
    graph = result.graph
    lines = [
        f"{graph_file}: {graph.dim}D, {graph.n_poses} poses, {graph.n_edges} edges",
        f"  cost before  {result.cost_before:.10g}",
        f"  cost after   {result.cost_after:.10g}",
        f"  {result.iterations} iterations, {result.seconds:.2f} s",
    ]
    if result.robust != "none":
        n_loops = int((~graph.is_odometry).sum())
        lines.append(f"  {result.robust} kernel rejects {len(result.rejected)} of {n_loops} loop closures")
    lines.append(f"wrote {out}")
    emit(summary, "\n".join(lines), as_json=as_json)


# ---------------------------------------------------------------------------------------------
# slam
# ---------------------------------------------------------------------------------------------


@app.command()
def slam(
    dive: DiveArg,
    loops: Annotated[
        Path | None,
        typer.Option(
            "--loops",
            help="Loop-closure file [DIVE/products/vision/loops.csv]; pose i is row i of the image times.",
        ),
    ] = None,
    compass_correction: Annotated[
        Path | None,
        typer.Option("--compass-correction", help="Compass correction file applied to the heading (eq. 5)."),
    ] = None,
    estimate_compass: Annotated[
        bool,
        typer.Option(
            "--estimate-compass",
            help="Estimate the deviation (eq. 5) in the graph; writes products/slam/compass_correction.yaml.",
        ),
    ] = False,
    incremental: Annotated[
        bool, typer.Option("--incremental", help="iSAM2 (a vehicle's solver), not batch Levenberg-Marquardt.")
    ] = False,
    poses_per_update: Annotated[
        int, typer.Option("--poses-per-update", min=1, help="With --incremental: poses per iSAM2 update.")
    ] = 10,
    tide: Annotated[
        Path | None,
        typer.Option("--tide", help="Tide constituent file: the depth becomes depth below the datum."),
    ] = None,
    compass_sigma_deg: Annotated[
        float | None,
        typer.Option(
            "--compass-sigma-deg",
            help="Heading sigma of the compass factors, deg [raw 10x the vehicle's; else 1x].",
        ),
    ] = None,
    harmonics: Annotated[
        int, typer.Option("--harmonics", min=0, help="Harmonics of the estimated deviation.")
    ] = 3,
    robust: Annotated[
        _RobustKernel, typer.Option("--robust", help="Kernel on loop closures; lists those it rejects.")
    ] = _RobustKernel.cauchy,
    marginal_every: Annotated[
        int,
        typer.Option("--marginal-every", min=0, help="Marginals of every Nth stereo pair (0: none)."),
    ] = 1,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """SLAM pose graph (GTSAM): DVL, attitude, depth, compass, fixes, loops; writes DIVE/products/slam/."""
    from auvnav.slam.products import format_summary, run_slam

    setup_logging(verbose, quiet)
    summary = run_slam(
        dive,
        loops=loops,
        compass_correction=compass_correction,
        estimate_compass=estimate_compass,
        incremental=incremental,
        poses_per_update=poses_per_update,
        tide=tide,
        compass_sigma_deg=compass_sigma_deg,
        harmonics=harmonics,
        robust=robust.value,
        marginal_every=marginal_every,
    )
    emit(summary, format_summary(summary), as_json=as_json)


if __name__ == "__main__":
    sys.exit(main())
