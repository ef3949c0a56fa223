"""``auvnav compass``: declination, magnetometer calibration, the deviation fit (eq. 5-6)."""

from __future__ import annotations

import inspect
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

from auvnav import products as P
from auvnav.cli.common import (
    JsonOpt,
    OverwriteOpt,
    QuietOpt,
    VerboseOpt,
    app,
    command_with,
    common_parameters,
    emit,
    setting_parameters,
    settings_from_options,
    setup_logging,
)

compass_app = typer.Typer(
    help="Compass: declination, magnetometer calibration, deviation fit.", no_args_is_help=True
)
app.add_typer(compass_app, name="compass")


class _Model(str, Enum):
    auto = "auto"
    wmm = "wmm"
    igrf = "igrf"


ModelOpt = Annotated[
    _Model,
    typer.Option(
        "--model",
        help="Geomagnetic model: wmm, igrf, or auto (WMM inside its years 2010-2030, IGRF-14 outside).",
    ),
]


def _date2posix(text: str) -> float:
    """POSIX seconds (UTC) of an ISO date ``YYYY-MM-DD`` or a decimal year such as ``2025.5``."""
    import datetime as dt

    from auvnav.compass.field import decimal_year2posix

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
    model: ModelOpt = _Model.auto,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """The geomagnetic field at a place and date (WMM, or IGRF outside the WMM years; --model to choose)."""
    import math

    from auvnav.compass.field import earth_field, posix2decimal_year

    setup_logging(verbose, quiet)
    time_s = _date2posix(date)
    field = earth_field(
        math.radians(lat_deg), math.radians(lon_deg), time_s, height_m=1e3 * height_km, model=model.value
    )
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


def _compass_fit(
    dives: list[Path],
    out: Path | None,
    overwrite: bool,
    as_json: bool,
    verbose: int,
    quiet: bool,
    **values: Any,
) -> None:
    from auvnav.compass.evaluate import TRUE_DEVIATION_FILE, read_true_deviation
    from auvnav.compass.stage import CompassSettings, fit_to_file, format_summary
    from auvnav.pipeline import run_stage

    setup_logging(verbose, quiet)
    settings = settings_from_options(CompassSettings, values)
    if out is None and len(dives) > 1:
        raise typer.BadParameter("several dives are fitted into a file of their own: give --out FILE")
    if out is None:
        summary = run_stage(dives[0], "compass", settings)
        run_stage(dives[0], "report")
        correction = P.COMPASS_CORRECTION.path(dives[0])
        figure = P.REPORT_FIGURES.path(dives[0]) / "fig5_compass.png"
    else:
        from auvnav.report.compass_figures import CorrectionFigure, plot_correction

        result = fit_to_file(dives, settings, out, overwrite=overwrite)
        summary = result.summary()
        correction, figure = out, out.with_suffix(".png")
        truth = read_true_deviation(dives[0]) if (dives[0] / TRUE_DEVIATION_FILE).is_file() else None
        plot_correction(CorrectionFigure.from_fit(result), figure, true_deviation=truth)
    summary = {"correction": str(correction), "figure": str(figure), **summary}
    emit(summary, format_summary(summary), as_json=as_json)


def _register_fit() -> None:
    from auvnav.compass.stage import CompassSettings

    kw = inspect.Parameter.KEYWORD_ONLY
    params = [
        inspect.Parameter(
            "dives",
            inspect.Parameter.POSITIONAL_OR_KEYWORD,
            annotation=Annotated[list[Path], typer.Argument(metavar="DIVE", help="Dive folders, pooled.")],
        ),
        *setting_parameters(CompassSettings),
        inspect.Parameter(
            "out",
            kw,
            default=None,
            annotation=Annotated[
                Path | None,
                typer.Option(
                    "--out",
                    help="Correction file for the dives pooled, with a .png beside it "
                    "[one dive: its compass stage, DIVE/products/compass/correction.yaml].",
                ),
            ],
        ),
        inspect.Parameter("overwrite", kw, default=False, annotation=OverwriteOpt),
        *common_parameters(),
    ]
    command_with(
        compass_app,
        "fit",
        "Fit the compass correction (eq. 5-6) against a reference heading; the constant from transits.",
        params,
        _compass_fit,
    )


_register_fit()


class _CalibrationMethod(str, Enum):
    auto = "auto"
    levelled = "levelled"
    ellipsoid = "ellipsoid"
    general = "general"


@compass_app.command("calibrate")
def compass_calibrate(
    dive: Annotated[
        Path | None,
        typer.Argument(metavar="DIVE", help="A dive folder with nav/magnetometer.csv (a spin)."),
    ] = None,
    samples: Annotated[
        Path | None,
        typer.Option(
            "--samples",
            help="Raw samples instead of a dive: a CSV with x, y, z (or mx, my, mz) in any one unit, "
            "optionally pitch_deg, roll_deg.",
        ),
    ] = None,
    method: Annotated[
        _CalibrationMethod,
        typer.Option(
            "--method",
            help="levelled: horizontal fit (a barely tilting spin); ellipsoid: 3D with attitude; general: "
            "3D from samples alone; auto: levelled for a dive, general or ellipsoid for samples.",
        ),
    ] = _CalibrationMethod.auto,
    field_model: Annotated[
        bool,
        typer.Option(
            "--field-model/--no-field-model",
            help="Reference the vertical to the geomagnetic model's inclination at the site and date "
            "(a dive's origin and start; for --samples, --latitude-deg --longitude-deg --date).",
        ),
    ] = True,
    latitude_deg: Annotated[
        float | None, typer.Option("--latitude-deg", help="--samples: where they were taken, degrees.")
    ] = None,
    longitude_deg: Annotated[
        float | None, typer.Option("--longitude-deg", help="--samples: where they were taken, degrees.")
    ] = None,
    date: Annotated[
        str | None, typer.Option("--date", help="--samples: when (YYYY-MM-DD or decimal year).")
    ] = None,
    model: ModelOpt = _Model.auto,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Hard- and soft-iron calibration from a dive's raw magnetometer (a spin), or from raw samples."""
    import math

    from auvnav.compass.calibrate import (
        calibrate_dive,
        calibrate_samples,
        format_calibration,
        format_samples_calibration,
    )

    setup_logging(verbose, quiet)
    if (dive is None) == (samples is None):
        raise typer.BadParameter("give a dive folder or --samples FILE.csv (one of them)", param_hint="DIVE")
    if samples is not None:
        site_given = [v is not None for v in (latitude_deg, longitude_deg, date)]
        if any(site_given) and not all(site_given):
            raise typer.BadParameter(
                "the field model needs --latitude-deg, --longitude-deg and --date together"
            )
        site = None
        if all(site_given) and field_model:
            site = (math.radians(latitude_deg), math.radians(longitude_deg), _date2posix(date))  # type: ignore[arg-type]
        summary = calibrate_samples(samples, method=method.value, site=site, model=model.value)
        emit(summary, format_samples_calibration(summary), as_json=as_json)
        return
    if method == _CalibrationMethod.general:
        raise typer.BadParameter("general is for --samples; a dive has attitude: use levelled or ellipsoid")
    dive_method = "levelled" if method == _CalibrationMethod.auto else method.value
    summary = calibrate_dive(dive, method=dive_method, field_model=field_model, model=model.value)  # type: ignore[arg-type]
    emit(summary, format_calibration(summary), as_json=as_json)
