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
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from auvnav.compass.field import earth_field
from auvnav.compass.magnetometer import CalibrationMethod, calibrate_magnetometer, heading_from_magnetometer
from auvnav.dive import read_dive
from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import FloatArray, angle_diff, wrap_angle
from auvnav.nav.inputs import declination
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
    doc = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    try:
        h = np.asarray(doc["compass"]["h_hard_body_nT"], dtype=float)
        field = float(np.linalg.norm(np.asarray(doc["earth_field"]["b_ned_nT"], dtype=float)))
    except (KeyError, TypeError, ValueError) as err:
        raise DiveFormatError([Problem(str(path), f"no usable hard iron or earth field ({err})")]) from err
    return h, field


def calibrate_dive(
    dive_path: Path, *, method: CalibrationMethod = "levelled", field_model: bool = True
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
        model = earth_field(origin.latitude_rad, origin.longitude_rad, dive.info.start_time_s)
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
