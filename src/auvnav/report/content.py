"""What a dive's report says: its facts, the stages that ran (and why the others did not), its headline
figures with their units, and (for a simulated dive scored by ``auvnav evaluate``) the same against the
truth. Read from the products only (``products/<stage>/stage.json`` and ``summary.json``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from auvnav import products as P
from auvnav.dive import (
    AttitudeStream,
    DvlStream,
    GpsStream,
    ImageIndex,
    MagnetometerStream,
    PressureStream,
    UsblStream,
    find_stream_file,
    read_dive_info,
)

#: The stages a report reads, in the pipeline's order (the report stage's ``after``).
STAGE_NAMES = ("nav", "vision", "slam", "compass", "depth", "coverage", "recon")
STAGE_TITLES = {
    "nav": "navigation",
    "vision": "visual loop closures",
    "slam": "SLAM",
    "compass": "compass correction",
    "depth": "depth check",
    "coverage": "coverage",
    "recon": "reconstruction",
}


@dataclass(frozen=True)
class Figure:
    """One headline figure: label, value with its unit, and the same scored against the truth."""

    label: str
    value: str
    truth: str = ""


@dataclass(frozen=True)
class DiveFacts:
    """A dive at a glance (module docstring)."""

    name: str
    start: str
    duration_s: float | None
    distance_m: float | None
    distance_source: str
    sensors: list[str]
    stages: dict[str, tuple[str, str]]  # stage -> (status, reason)
    figures: list[Figure] = field(default_factory=list)
    simulated: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "start": self.start,
            "duration_s": self.duration_s,
            "distance_m": self.distance_m,
            "distance_source": self.distance_source,
            "sensors": self.sensors,
            "stages": {k: {"status": s, "reason": r} for k, (s, r) in self.stages.items()},
            "figures": [{"label": f.label, "value": f.value, "truth": f.truth} for f in self.figures],
            "simulated": self.simulated,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DiveFacts:
        return cls(
            name=data["name"],
            start=data["start"],
            duration_s=data["duration_s"],
            distance_m=data["distance_m"],
            distance_source=data.get("distance_source", ""),
            sensors=list(data["sensors"]),
            stages={k: (v["status"], v["reason"]) for k, v in data["stages"].items()},
            figures=[Figure(**f) for f in data["figures"]],
            simulated=bool(data.get("simulated")),
        )


def _summary(dive: Path, product: P.Product) -> dict[str, Any]:
    path = product.path(dive)
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _num(value: Any, fmt: str, unit: str = "", scale: float = 1.0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{scale * float(value):{fmt}}{(' ' + unit) if unit else ''}"


def _sensors(dive: Path) -> list[str]:
    out = []
    for cls, name in (
        (DvlStream, "DVL"),
        (AttitudeStream, "compass and attitude"),
        (PressureStream, "pressure"),
        (MagnetometerStream, "magnetometer"),
        (GpsStream, "GPS"),
        (UsblStream, "USBL"),
    ):
        if find_stream_file(dive, cls.FILE) is not None:
            out.append(name)
    index = find_stream_file(dive, ImageIndex.FILE)
    if index is not None:
        with open(index, "rb") as fh:
            pairs = max(0, sum(1 for _ in fh) - 1)
        out.append(f"stereo camera ({pairs:,} pairs)")
    return out


def _stages(dive: Path) -> dict[str, tuple[str, str]]:
    out = {}
    for name in STAGE_NAMES:
        record = P.read_record(dive, name)
        if record is None:
            out[name] = ("not run", "no products: the stage has not been run on this dive")
        else:
            out[name] = (str(record.get("status", "ran")), str(record.get("reason") or ""))
    return out


def dive_facts(dive: Path, evaluation: dict[str, Any] | None = None) -> DiveFacts:
    """The dive's facts and headline figures from its products; ``evaluation`` (``auvnav evaluate``'s
    result for a simulated dive) adds the figures against the truth."""
    dive = Path(dive)
    info = read_dive_info(dive)
    ev = evaluation or {}
    nav = _summary(dive, P.NAV_SUMMARY)
    vision = _summary(dive, P.VISION_SUMMARY)
    slam = _summary(dive, P.SLAM_SUMMARY)
    compass = _summary(dive, P.COMPASS_SUMMARY)
    depth = _summary(dive, P.DEPTH_SUMMARY)
    coverage = _summary(dive, P.COVERAGE_SUMMARY)
    recon = _summary(dive, P.RECON_SUMMARY)
    figures: list[Figure] = []

    def add(label: str, value: str, truth: str = "") -> None:
        if value != "-" or truth:
            figures.append(Figure(label, value, truth))

    e_dr, e_f, e_s = ev.get("dr") or {}, ev.get("filter") or {}, ev.get("slam") or {}
    end = nav.get("end_fix") or {}
    add(
        "dead reckoning at the last fix",
        _num(end.get("dr_error_m"), ".2f", "m") + " from the fix" if end else "-",
        f"end error {_num(e_dr.get('end_error_m'), '.2f', 'm')} ({_num(e_dr.get('end_error_pct'), '.2f', '%')} of the distance); "
        f"ATE aligned {_num(e_dr.get('ate_aligned_rmse_m'), '.3f', 'm')}"
        if e_dr
        else "",
    )
    add(
        "filter: innovations inside 2 sigma",
        _num(nav.get("innovations_inside_2sigma"), ".1f", "%", 100.0),
        f"end error {_num(e_f.get('end_error_m'), '.2f', 'm')}; ATE aligned {_num(e_f.get('ate_aligned_rmse_m'), '.3f', 'm')}"
        if e_f
        else "",
    )
    if vision:
        lo = ev.get("loops") or {}
        add(
            "loop closures (not consecutive)",
            f"{vision.get('nonconsecutive_accepted', 0):,} of {vision.get('candidates_tested', 0):,} pairs tested"
            + (f"; {vision['direct_accepted']:,} from the images" if vision.get("direct_accepted") else ""),
            f"recall {_num(lo.get('recall'), '.3f')}, precision {_num(lo.get('precision'), '.3f')}, median error "
            f"{_num(lo.get('translation_error_median_m'), '.1f', 'mm', 1000.0)}"
            if lo
            else "",
        )
    if slam:
        loops = slam.get("loops") or {}
        add(
            "SLAM",
            f"{slam.get('poses', 0):,} poses; {loops.get('used', 0):,} loop closures, {loops.get('rejected', 0):,} rejected",
            f"ATE aligned {_num(e_s.get('ate_aligned_rmse_m'), '.3f', 'm')}, end error {_num(e_s.get('end_error_m'), '.2f', 'm')}, "
            f"yaw RMSE {_num(e_s.get('yaw_rmse_deg'), '.3f', 'deg')}"
            if e_s
            else "",
        )
    if compass:
        ec = ev.get("compass") or {}
        add(
            "compass correction",
            f"{compass.get('harmonics')} harmonics, residual RMS {_num(compass.get('residual_rms_deg'), '.3f', 'deg')}; "
            f"constant {_num(compass.get('a0_deg'), '+.3f', 'deg')} ({(compass.get('constant') or {}).get('source', '?')})",
            f"against the true deviation: RMS {_num(ec.get('deviation_rmse_deg'), '.3f', 'deg')}, max "
            f"{_num(ec.get('deviation_max_error_deg'), '.3f', 'deg')}"
            if ec
            else "",
        )
    if depth:
        ed = ev.get("depth") or {}
        add(
            "depth: loop-closure residual RMS before / after the tide",
            f"{_num(depth.get('residual_rms_before_m'), '.3f', 'm')} / {_num(depth.get('residual_rms_after_m'), '.3f', 'm')}",
            f"{_num(ed.get('residual_rms_before_m'), '.3f', 'm')} / {_num(ed.get('residual_rms_after_m'), '.3f', 'm')}"
            if ed
            else "",
        )
    if coverage:
        ecov = ev.get("coverage") or {}
        add(
            "coverage",
            f"{_num(coverage.get('coverage_pct'), '.1f', '%')}, gaps {_num((coverage.get('gaps') or {}).get('area_m2'), '.1f', 'm²')}",
            f"true coverage {_num(ecov.get('coverage_pct_true'), '.1f', '%')}, true gaps {_num(ecov.get('gap_area_true_m2'), '.1f', 'm²')}, "
            f"spacing RMSE {_num(ecov.get('spacing_rmse_m'), '.1f', 'cm', 100.0)}"
            if ecov
            else "",
        )
    if recon:
        er = ev.get("recon") or {}
        rel = recon.get("relief") or {}
        add(
            "reconstruction",
            f"DEM {_num((recon.get('dem') or {}).get('area_m2'), '.0f', 'm²')} from {(recon.get('pairs') or {}).get('used', 0):,} pairs; "
            f"mesh {(recon.get('mesh') or {}).get('faces', 0):,} triangles",
            f"DEM RMSE {_num(er.get('dem_rmse_m'), '.1f', 'mm', 1000.0)}, orthophoto misregistration median "
            f"{_num(er.get('mosaic_misregistration_median_px'), '.2f', 'px')}"
            if er
            else "",
        )
        add(
            "false relief on revisits, RMS before / after the tide",
            f"{_num(rel.get('step_before_rms_m'), '.1f', 'cm', 100.0)} / {_num(rel.get('step_after_rms_m'), '.1f', 'cm', 100.0)}",
            f"{_num(er.get('relief_step_before_m'), '.1f', 'cm', 100.0)} / {_num(er.get('relief_step_after_m'), '.1f', 'cm', 100.0)}"
            if er
            else "",
        )
    truth_distance = ev.get("distance_m") is not None
    distance = ev.get("distance_m") if truth_distance else nav.get("dr_distance_m")
    return DiveFacts(
        name=dive.resolve().name,  # the folder: a campaign's dives may share dive.yaml's name
        start=_iso(info.start_time_s),
        duration_s=nav.get("duration_s"),
        distance_m=distance,
        distance_source="truth" if truth_distance else "dead reckoning",
        sensors=_sensors(dive),
        stages=_stages(dive),
        figures=figures,
        simulated=(dive / "truth").is_dir(),
    )


def _iso(t_s: float) -> str:
    import datetime

    return datetime.datetime.fromtimestamp(t_s, tz=datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
