"""The depth stage (``auvnav depth``): pressure depth checked against loop closures (paper Fig. 6).

Products (DESIGN section 6), in ``DIVE/products/depth/``: ``loop_depth.csv``
(:class:`~auvnav.depth.validation.LoopDepth`), ``summary.json``
(:meth:`~auvnav.depth.validation.DepthResult.summary`) and, with ``estimate_tide``,
``tide_estimated.csv`` (a constituent file, :mod:`auvnav.depth.estimation`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from auvnav import products as P
from auvnav.dive import ImageIndex, dive_files, find_stream_file, read_dive
from auvnav.errors import InsufficientDataError
from auvnav.stagekit import Stage, StageContext, setting
from auvnav.streams import atomic_write, write_json, write_stream
from auvnav.vision.loopfile import check_loop_times, loops_file, read_loops

if TYPE_CHECKING:  # the models load when the stage runs, not when the pipeline checks its key
    from auvnav.depth.validation import DepthResult

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DepthSettings:
    """Settings of the depth stage."""

    tide: Path | None = setting(None, "Tide constituent file (name, amplitude_m, phase_deg) to correct with.")
    atmospheric: Path | None = setting(
        None, "Atmospheric pressure series (t, pressure_dbar) [dive.yaml's constant]."
    )
    estimate_tide: bool = setting(False, "Estimate the tide from the loop closures alone.")
    loops: Path | None = setting(None, "Loop-closure file [DIVE/products/vision/loops.csv].")


def write_products(result: DepthResult, out: Path) -> None:
    """Write the stage's products into ``out`` (a stage folder being written)."""
    from auvnav.depth.tide import write_constituents

    write_stream(result.loops, P.DEPTH_LOOPS.inside(out))
    write_json(result.summary(), P.DEPTH_SUMMARY.inside(out))
    if result.estimate is not None:
        model = result.estimate.model
        atomic_write(P.DEPTH_TIDE_ESTIMATED.inside(out), lambda p: write_constituents(model, p))


def _unavailable(dive: Path, settings: DepthSettings) -> str | None:
    if find_stream_file(dive, ImageIndex.FILE) is None:
        return "no loop closures: the dive has no images/index.csv, whose rows they name"
    if loops_file(dive, settings.loops) is None:
        return (
            "no loop closures (products/vision/loops.csv: run the loop-closure stage, or give --loops FILE)"
        )
    return None


def _inputs(dive: Path, settings: DepthSettings) -> dict[str, Path]:
    files = dive_files(dive)
    index = find_stream_file(dive, ImageIndex.FILE)
    if index is not None:
        files[str(index.relative_to(dive))] = index
    loops = loops_file(dive, settings.loops)
    if loops is not None:
        files["loops"] = loops
    for name in ("tide", "atmospheric"):
        if getattr(settings, name) is not None:
            files[name] = getattr(settings, name)
    return files


def _run(ctx: StageContext, settings: DepthSettings, out: Path) -> dict[str, Any]:
    from auvnav.depth.pressure import read_atmospheric
    from auvnav.depth.tide import read_constituents
    from auvnav.depth.validation import check_depth

    dive = read_dive(ctx.dive, allow_outside=ctx.allow_outside)
    loops_path = loops_file(ctx.dive, settings.loops)
    if dive.images is None or loops_path is None or not loops_path.is_file():
        shown = loops_path or P.LOOPS.path(ctx.dive)
        raise InsufficientDataError(f"{shown}: no loop closures (run 'auvnav loops' or give --loops FILE)")
    loops = read_loops(loops_path, n_poses=len(dive.images))
    check_loop_times(loops, dive.images.t_s, str(loops_path))
    latitude_rad = dive.info.origin.latitude_rad
    tide = None if settings.tide is None else read_constituents(settings.tide, latitude_rad=latitude_rad)
    atmospheric_path = settings.atmospheric
    atmospheric = None if atmospheric_path is None else read_atmospheric(atmospheric_path)
    if atmospheric is not None and dive.info.pressure_type == "sea":
        log.warning("%s: the dive's pressure is sea pressure; %s is not used", ctx.dive, atmospheric_path)
        atmospheric, atmospheric_path = None, None
    result = check_depth(
        dive,
        loops,
        loops_file=str(loops_path),
        tide=tide,
        tide_source=None if settings.tide is None else str(settings.tide),
        atmospheric_pa=atmospheric,
        atmospheric_source=None if atmospheric_path is None else str(atmospheric_path),
        estimate=settings.estimate_tide,
    )
    write_products(result, out)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`DepthResult.summary`."""

    def cm(value: float | None) -> str:
        return "-" if value is None else f"{100 * value:.1f} cm"

    tide = summary["tide"]
    lines = [
        f"dive '{summary['dive']}': {summary['n_loops']} loop closures from {summary['loops_file']}"
        + (f" ({summary['n_dropped']} left out: no pressure or DVL there)" if summary["n_dropped"] else ""),
        f"tide correction: {'none' if tide is None else tide['source']}; "
        f"atmospheric pressure: {summary['atmospheric']}",
        f"{'residual RMS':26s} {'n':>6s} {'before':>10s} {'after':>10s}",
    ]
    for label, key in (("all loops", None), ("far apart (> {:.0f} min)", "far_apart"), ("near", "near")):
        s = summary if key is None else summary[key]
        n = summary["n_loops"] if key is None else s["n"]
        lines.append(
            f"  {label.format(summary['far_apart_s'] / 60):24s} {n:6d} "
            f"{cm(s['residual_rms_before_m']):>10s} {cm(s['residual_rms_after_m']):>10s}"
        )
    lines.append(f"median 1-sigma of a residual: {cm(summary['sigma_median_m'])}")
    after = summary["false_relief_after"]
    lines.append(
        f"false-relief steps (far apart, > {cm(summary['relief_step_m'])} and 3 sigma): "
        f"{summary['false_relief_before']} before correction" + ("" if after is None else f", {after} after")
    )
    est = summary["estimated_tide"]
    if est is not None:
        lines.append(
            f"tide estimated from {est['n_used']} loops over {est['record_h']:.2f} h "
            f"({est['n_outliers']} outliers): fit RMS {cm(est['rms_fit_m'])}, "
            f"tide change known to {cm(est['change_sigma_rms_m'])} RMS (1 sigma)"
        )
        for c in est["constituents"]:
            kind = (
                "resolved"
                if c["resolved"]
                else f"effective (resolving needs {c['resolving_record_h']:.0f} h)"
            )
            lines.append(
                f"  {c['name']:3s} {c['amplitude_m']:.3f} +- {c['amplitude_sigma_m']:.3f} m, "
                f"phase {c['phase_deg']:.1f} +- {c['phase_sigma_deg']:.1f} deg, {kind}"
            )
        if "change_rms_vs_tide_m" in est:
            lines.append(
                f"  estimated minus given tide change: {cm(est['change_rms_vs_tide_m'])} RMS, "
                f"{cm(est['change_rms_vs_tide_far_apart_m'])} on far-apart loops"
            )
    return "\n".join(lines)


STAGE = Stage(
    name="depth",
    title="pressure depth against the vertical of loop closures, tide correction (Fig. 6)",
    after=("vision",),
    settings=DepthSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
)
