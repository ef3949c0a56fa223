"""Magnetometer calibration of a dive (``auvnav compass calibrate``): hard and soft iron from its raw
magnetometer, and the heading it gives against the logged compass and, in simulation, the truth.

The calibration is :func:`auvnav.compass.calibrate_magnetometer` on every sample of
``nav/magnetometer.csv`` (a spin: several full turns), levelled with the attitude's pitch and roll
interpolated at the magnetometer's times. By default its vertical is referenced to the inclination
of the geomagnetic model (:func:`auvnav.compass.field.earth_field`) at the dive's origin and start,
which fixes the vertical hard iron even from a level spin (what that assumes, and the 0.4% of the
field that the model's error costs on real data, are in :mod:`auvnav.compass.magnetometer`). The
calibrated heading (eq. 1) is compared with the compass heading as logged and, when the dive has
``truth/``, with the true magnetic heading: a calibration cannot see a rotation of the field about
the vertical (the deviation's constant term), so against the truth it is scored after removing its
mean offset, which is reported separately.
``truth/truth.yaml`` also gives the injected hard iron, scored as a fraction of the field.

:func:`calibrate_samples` calibrates raw samples from a CSV alone (``auvnav compass calibrate
--samples FILE.csv``): columns ``x, y, z`` (or ``mx, my, mz``) in any one unit, and optionally
``pitch_deg, roll_deg``. Without attitude it is the general ellipsoid fit from the samples alone
(hard iron and symmetric soft iron, :func:`auvnav.compass.magnetometer.fit_general`); with attitude
the 3-D fit whose levelled field is constant (``ellipsoid``, the default) or the levelled fit, and
with a site and date (``--latitude-deg --longitude-deg --date``) the field model's inclination
references the vertical. Degenerate samples are an error that says what is missing.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import numpy as np

from auvnav.compass.field import ModelChoice, earth_field
from auvnav.compass.magnetometer import CalibrationMethod, calibrate_magnetometer, heading_from_magnetometer
from auvnav.config import load_yaml
from auvnav.dive import MagnetometerStream, find_stream_file, read_dive
from auvnav.errors import ConfigError, DiveFormatError, InsufficientDataError, Problem
from auvnav.frames import FloatArray, angle_diff, wrap_angle
from auvnav.nav.inputs import declination
from auvnav.streams import Field, read_table
from auvnav.trajectory import read_trajectory

TRUTH_DIR = Path("truth")


def _interp_angle(t_s: FloatArray, t_src: FloatArray, a_rad: FloatArray) -> FloatArray:
    return wrap_angle(np.interp(t_s, t_src, np.unwrap(a_rad)))


def _offset_and_rms_deg(error_rad: FloatArray) -> tuple[float, float, float]:
    """Circular mean of the error, RMS about it and RMS about zero, degrees."""
    mean = float(np.angle(np.mean(np.exp(1j * error_rad))))
    about_mean = angle_diff(error_rad, mean)
    return (
        math.degrees(mean),
        math.degrees(float(np.sqrt(np.mean(about_mean**2)))),
        math.degrees(float(np.sqrt(np.mean(error_rad**2)))),
    )


def _true_hard_iron_nT(dive_path: Path) -> tuple[FloatArray, float] | None:
    """The simulator's hard iron (nT, body FRD) and total field (nT), or None without them."""
    path = dive_path / TRUTH_DIR / "truth.yaml"
    if not path.is_file():
        return None
    doc, problems = load_yaml(path, str(path))
    if problems:
        raise DiveFormatError(problems)
    try:
        h = np.asarray(doc["compass"]["h_hard_body_nT"], dtype=float)
        field = float(np.linalg.norm(np.asarray(doc["earth_field"]["b_ned_nT"], dtype=float)))
    except (KeyError, TypeError, ValueError) as err:
        raise DiveFormatError([Problem(str(path), f"no usable hard iron or earth field ({err})")]) from err
    return h, field


@contextlib.contextmanager
def _naming(path: Path) -> Iterator[None]:
    """Degenerate samples are a one-line error that names their file."""
    try:
        yield
    except InsufficientDataError as err:
        raise InsufficientDataError(f"{path}: {err}") from None


def calibrate_dive(
    dive_path: Path,
    *,
    method: CalibrationMethod = "levelled",
    field_model: bool = True,
    model: ModelChoice = "auto",
) -> dict[str, Any]:
    """Calibrate a dive's magnetometer and score the heading it gives.

    Parameters
    ----------
    dive_path : Path
        A dive folder with ``nav/magnetometer.csv`` (a spin, ideally).
    method : {"levelled", "ellipsoid"}
        ``"levelled"`` suits a passively stable vehicle, whose spin barely tilts. ``"ellipsoid"``
        needs tilt well above the inclinometer's error to separate the vertical scale and offset.
    field_model : bool
        Reference the vertical to the geomagnetic model's inclination at the dive's origin and
        start (``field_model`` in the summary names the model). Without it a levelled fit leaves
        the vertical offset at zero (e.g. at a site with a known magnetic anomaly).
    model : {"auto", "wmm", "igrf"}
        The geomagnetic model (:func:`auvnav.compass.field.earth_field`).

    Returns
    -------
    dict
        :meth:`MagnetometerCalibration.summary` plus ``field_model`` (the geomagnetic model's
        name, or None), ``field_unit`` (mean calibrated magnitude, in the file's unit),
        ``heading_vs_compass`` (``offset_deg``, ``rms_deg`` about the offset, calibrated minus
        logged compass) and, for a simulated dive, ``truth``: ``heading_offset_deg``,
        ``heading_rms_deg`` (about the offset), ``compass_rms_deg`` (the logged compass against the
        truth, offset included) and ``hard_iron_error_pct`` (per axis, of the total field; the
        vertical None when the fit left it at zero).

    Raises
    ------
    DiveFormatError
        The dive has no magnetometer stream (one line naming the file), or is bad.
    GeomagneticModelError
        ``field_model`` and no model covers the dive's date.
    InsufficientDataError
        Too few samples, or samples that do not turn through all headings.
    """
    dive_path = Path(dive_path)
    dive = read_dive(dive_path)
    model_choice = model
    mag = dive.magnetometer
    if mag is None:
        raise DiveFormatError(
            [
                Problem(
                    str(dive_path / "nav" / "magnetometer.csv"),
                    "not found: calibration needs the raw magnetometer",
                )
            ]
        )
    att = dive.attitude
    pitch = np.interp(mag.t_s, att.t_s, att.pitch_rad)
    roll = _interp_angle(mag.t_s, att.t_s, att.roll_rad)
    model = None
    if field_model:
        origin = dive.info.origin
        model = earth_field(
            origin.latitude_rad, origin.longitude_rad, dive.info.start_time_s, model=model_choice
        )
    with _naming(
        find_stream_file(dive_path, MagnetometerStream.FILE) or dive_path / "nav" / "magnetometer.csv"
    ):
        cal = calibrate_magnetometer(
            mag.m_body,
            pitch,
            roll,
            method=method,
            inclination_rad=None if model is None else model.inclination_rad,
        )
    calibrated = cal.apply(mag.m_body)
    heading = heading_from_magnetometer(calibrated, pitch, roll)
    compass = _interp_angle(mag.t_s, att.t_s, att.heading_rad)
    offset, rms, _ = _offset_and_rms_deg(angle_diff(heading, compass))
    field_unit = float(np.mean(np.linalg.norm(calibrated, axis=1)))
    summary: dict[str, Any] = {
        "dive": dive_path.name,
        **cal.summary(),
        "field_model": None if model is None else model.model,
        "field_unit": field_unit,
        "heading_vs_compass": {"offset_deg": offset, "rms_deg": rms},
        "truth": None,
    }
    truth_path = dive_path / TRUTH_DIR / "trajectory.csv"
    if truth_path.is_file():
        truth = read_trajectory(truth_path)
        inside = (mag.t_s >= truth.t_s[0]) & (mag.t_s <= truth.t_s[-1])
        decl, _ = declination(dive)
        true_magnetic = wrap_angle(truth.interpolate(mag.t_s[inside]).yaw_rad - decl)
        offset, rms, _ = _offset_and_rms_deg(angle_diff(heading[inside], true_magnetic))
        _, _, compass_rms = _offset_and_rms_deg(angle_diff(compass[inside], true_magnetic))
        scores: dict[str, Any] = {
            "heading_offset_deg": offset,
            "heading_rms_deg": rms,
            "compass_rms_deg": compass_rms,
            "hard_iron_error_pct": None,
        }
        hard = _true_hard_iron_nT(dive_path)
        if hard is not None:
            h_true_nT, field_nT = hard
            # The file's unit from the calibrated magnitude, so any unit compares with the truth's nT.
            error = 100.0 * (cal.h_hard_body * field_nT / field_unit - h_true_nT) / field_nT
            scores["hard_iron_error_pct"] = [
                float(error[0]),
                float(error[1]),
                float(error[2]) if cal.vertical_determined else None,
            ]
        summary["truth"] = scores
    return summary


def format_calibration(summary: dict[str, Any]) -> str:
    """A short human-readable account of :func:`calibrate_dive`'s summary."""
    h = summary["h_hard_body"]
    unit = summary["field_unit"]
    reference = (
        ""
        if summary["field_model"] is None
        else f", vertical referenced to {summary['field_model']} "
        f"(inclination {summary['inclination_deg']:+.2f} deg)"
    )
    lines = [
        f"{summary['dive']}: {summary['method']} calibration of {summary['n_samples']} magnetometer "
        f"samples{reference}",
        "  hard iron   [{}] ({} of the field)".format(
            ", ".join(f"{v:.4g}" for v in h), ", ".join(f"{100 * v / unit:+.2f}%" for v in h)
        ),
        "  soft iron   " + "; ".join(" ".join(f"{v:+.4f}" for v in row) for row in summary["A_soft"]),
        f"  field spread {summary['field_spread_before_pct']:.2f}% before, "
        f"{summary['field_spread_after_pct']:.3f}% after (levelled horizontal "
        f"{summary['horizontal_spread_before_pct']:.2f}% -> "
        f"{summary['horizontal_spread_after_pct']:.3f}%)",
        f"  calibrated minus logged compass: offset {summary['heading_vs_compass']['offset_deg']:+.2f} deg, "
        f"RMS {summary['heading_vs_compass']['rms_deg']:.2f} deg about it",
    ]
    truth = summary["truth"]
    if truth is not None:
        lines.append(
            f"  against the truth: heading RMS {truth['heading_rms_deg']:.3f} deg about an offset of "
            f"{truth['heading_offset_deg']:+.2f} deg (the logged compass: {truth['compass_rms_deg']:.2f} deg RMS)"
        )
        if truth["hard_iron_error_pct"] is not None:
            lines.append(
                "  hard-iron error: "
                + ", ".join("n/a" if v is None else f"{v:+.3f}%" for v in truth["hard_iron_error_pct"])
                + " of the field"
            )
    return "\n".join(lines)


DEG = math.pi / 180.0
SampleMethod = Literal["auto", "general", "ellipsoid", "levelled"]


def _sample_fields(columns: tuple[str, str, str]) -> tuple[Field, ...]:
    return (
        Field("m", columns),
        Field("pitch_rad", ("pitch_deg",), DEG, required=False),
        Field("roll_rad", ("roll_deg",), DEG, required=False),
    )


def read_samples(path: Path) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """Magnetometer samples (N, 3) and, when the file has them, pitch and roll (radians)."""
    path = Path(path)
    header = ""
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    header = line
                    break
    except (OSError, UnicodeDecodeError):
        pass  # read_table says why
    names = [c.strip() for c in header.split(",")]
    columns = ("mx", "my", "mz") if "mx" in names else ("x", "y", "z")
    values, problems, _warnings = read_table(path, _sample_fields(columns), str(path), time_ordered=False)
    if problems:
        raise DiveFormatError(problems)
    m = np.column_stack([values[c] for c in columns]).astype(float)
    if ("pitch_deg" in values) != ("roll_deg" in values):
        raise ConfigError(f"{path}: give both pitch_deg and roll_deg, or neither")
    if "pitch_deg" in values:
        return m, np.asarray(values["pitch_deg"], float) * DEG, np.asarray(values["roll_deg"], float) * DEG
    return m, None, None


def calibrate_samples(
    path: Path,
    *,
    method: SampleMethod = "auto",
    site: tuple[float, float, float] | None = None,
    model: ModelChoice = "auto",
) -> dict[str, Any]:
    """Calibrate raw magnetometer samples from a CSV (the module's notes).

    Parameters
    ----------
    path : Path
        CSV with ``x, y, z`` (or ``mx, my, mz``), any one unit; optionally ``pitch_deg, roll_deg``.
    method : {"auto", "general", "ellipsoid", "levelled"}
        ``auto``: ``general`` without attitude, ``ellipsoid`` with it.
    site : (latitude_rad, longitude_rad, time_s), optional
        Where and when: the field model's inclination references the vertical (needs attitude).
    model : {"auto", "wmm", "igrf"}

    Returns
    -------
    dict
        :meth:`MagnetometerCalibration.summary` plus ``samples``, ``attitude`` (whether the file had
        it), ``field_model`` (or None), ``field_unit`` (mean calibrated magnitude, the samples' unit)
        and ``notes``.

    Raises
    ------
    DiveFormatError
        The file is not a readable CSV of samples (every problem, with row and column).
    ConfigError
        A method that needs attitude on samples without it.
    InsufficientDataError
        Degenerate samples; the message says what is missing.
    """
    m, pitch, roll = read_samples(Path(path))
    notes: list[str] = []
    attitude = pitch is not None
    if method == "auto":
        method = "ellipsoid" if attitude else "general"
    if not attitude and method in ("ellipsoid", "levelled"):
        raise ConfigError(f"{path}: the {method} calibration needs pitch_deg and roll_deg columns")
    field = None
    if site is not None:
        field = earth_field(site[0], site[1], site[2], model=model)
        if not attitude or method == "general":
            notes.append(
                "the field model's inclination needs pitch and roll to reference the vertical: not used"
            )
            field = None
    with _naming(Path(path)):
        cal = calibrate_magnetometer(
            m,
            0.0 if pitch is None else pitch,
            0.0 if roll is None else roll,
            method=method,  # type: ignore[arg-type]
            inclination_rad=None if field is None else field.inclination_rad,
        )
    unit = float(np.mean(np.linalg.norm(cal.apply(m), axis=1)))
    return {
        "samples": str(path),
        **cal.summary(),
        "attitude": attitude,
        "field_model": None if field is None else field.model,
        "field_unit": unit,
        "notes": notes,
    }


def format_samples_calibration(summary: dict[str, Any]) -> str:
    """A short human-readable account of :func:`calibrate_samples`' summary."""
    h, unit = summary["h_hard_body"], summary["field_unit"]
    reference = (
        ""
        if summary["field_model"] is None
        else f", vertical referenced to {summary['field_model']} (inclination {summary['inclination_deg']:+.2f} deg)"
    )
    lines = [
        f"{summary['samples']}: {summary['method']} calibration of {summary['n_samples']} magnetometer samples"
        f" ({'with' if summary['attitude'] else 'without'} attitude){reference}",
        "  hard iron   [{}] ({} of the field)".format(
            ", ".join(f"{v:.4g}" for v in h), ", ".join(f"{100 * v / unit:+.2f}%" for v in h)
        ),
        "  soft iron   " + "; ".join(" ".join(f"{v:+.4f}" for v in row) for row in summary["A_soft"]),
        f"  field spread {summary['field_spread_before_pct']:.2f}% before, {summary['field_spread_after_pct']:.3f}% after",
    ]
    if summary["hard_iron_sigma_pct"] is not None:
        lines.append(
            "  hard-iron 1-sigma (formal): "
            + ", ".join(f"{v:.3f}%" for v in summary["hard_iron_sigma_pct"])
            + " of the field"
        )
    lines.extend(f"  note: {n}" for n in summary["notes"])
    return "\n".join(lines)
