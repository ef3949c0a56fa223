"""``auvnav demo``: the paper's experiment on a built-in simulated campaign.

The campaign mirrors the Scott Reef cruise of the paper (section IV): a navigation check dive (star of
reciprocal legs plus a grid, section III-A), long sub-sea transits between GPS fixes (for the compass
correction's constant, Fig. 5b), and the 75 m x 50 m full-coverage survey (section IV-A) flown three
ways: with the vehicle's compass as it is, with the deviation removed (the best the DVL allows), and with
the correction fitted from the check dive. Every stage that exists runs on it and its figures are
measured against the simulator's truth; the summary says which stages do not exist yet rather than
pretending they ran.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from auvnav.errors import OutputExistsError
from auvnav.streams import write_json

log = logging.getLogger(__name__)

#: Stages of the paper that the demo cannot run yet; each issue that lands removes its line.
NOT_YET = (
    "coverage analysis ('accordion', 'figure 8'), dense 3D reconstruction and mosaics, and the HTML "
    "report: not built yet",
)


@dataclass(frozen=True)
class Campaign:
    """The dives of the demo: generator geometry per scenario, seeds, and the size of the check dive's
    stereo images (the surveys' SLAM and depth check use the simulator's truth-derived loop closures:
    rendering 2.5 hours of survey would take most of an hour on two cores)."""

    navcheck: dict[str, Any] = field(default_factory=dict)
    transit: dict[str, Any] = field(default_factory=dict)
    survey: dict[str, Any] = field(default_factory=dict)
    seeds: dict[str, int] = field(default_factory=lambda: {"navcheck": 1, "transit": 2, "survey": 3})
    image_scale: float = 0.5  # half the Sirius cameras' size, where the paper's group ran SIFT


FULL = Campaign()
QUICK = Campaign(
    navcheck={"headings": 8, "leg_m": 20.0, "grid_m": 6.0},
    transit={"legs": 4, "leg_m": 400.0},
    survey={"width_m": 20.0, "height_m": 20.0, "lead_in_m": 20.0},
    image_scale=0.25,
)

Progress = Callable[[str], None]


def _throttled(say: Progress, every_s: float = 30.0) -> Callable[[str, int, int], None]:
    """A ``(what, done, total)`` counter that says ``what done/total`` when ``what`` changes and at
    most every ``every_s`` seconds otherwise."""
    last, last_what = time.monotonic(), ""

    def tick(what: str, done: int, total: int) -> None:
        nonlocal last, last_what
        now = time.monotonic()
        if what != last_what or now - last >= every_s:
            last, last_what = now, what
            say(f"  {what} {done}/{total}")

    return tick


def _simulate(
    out: Path, name: str, scenario: str, geometry: dict[str, Any], seed: int, **options: Any
) -> dict[str, Any]:
    from auvnav.sim.run import run_scenario

    return run_scenario(scenario, out / name, seed=seed, geometry=geometry, overwrite=True, **options)


def _navigate_and_score(dive: Path, correction: Path | None = None) -> dict[str, Any]:
    from auvnav.evaluate import evaluate_dive
    from auvnav.nav.products import run_navigation

    nav = run_navigation(dive, compass_correction=correction)
    return {"navigation": nav, "evaluation": evaluate_dive(dive, compass_correction=correction)}


#: Where the compass fit takes its reference headings: SLAM, as in the paper.
COMPASS_REFERENCE = "slam"


def run_demo(
    out: Path, *, quick: bool = False, overwrite: bool = False, progress: Progress | None = None
) -> dict[str, Any]:
    """Simulate the campaign into ``out`` and run every stage that exists; return the measurements.

    Parameters
    ----------
    out : Path
        Folder for the dives and the summary; must not exist unless ``overwrite``.
    quick : bool
        Small geometry and quarter-scale images (about 4 minutes on two cores instead of 25).
    overwrite : bool
    progress : callable, optional
        Called with a line of text as each step starts.
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda text: log.info(text))
    campaign = QUICK if quick else FULL
    dives: dict[str, dict[str, Any]] = {}

    plan = [
        ("navcheck", "navcheck", campaign.navcheck, campaign.seeds["navcheck"], {}),
        ("transit", "transit", campaign.transit, campaign.seeds["transit"], {}),
        ("survey-uncorrected", "survey", campaign.survey, campaign.seeds["survey"], {}),
        ("survey-no-deviation", "survey", campaign.survey, campaign.seeds["survey"], {"deviation": "none"}),
    ]
    for name, scenario, geometry, seed, options in plan:
        say(f"simulating {name}")
        sim = _simulate(out, name, scenario, geometry, seed, **options)
        say(f"navigating {name}")
        dives[name] = {"simulation": sim, **_navigate_and_score(out / name)}

    from auvnav.evaluate import evaluate_dive
    from auvnav.nav.products import run_navigation
    from auvnav.report.compass_figures import run_compass_fit
    from auvnav.report.depth_figures import depth_products
    from auvnav.sim.camera import render_dive_images
    from auvnav.slam.products import run_slam
    from auvnav.vision.loops import run_loop_stage

    navcheck = out / "navcheck"
    tick = _throttled(say)
    say(f"rendering navcheck's stereo images ({campaign.image_scale:g} scale)")
    render_dive_images(
        navcheck,
        scale=campaign.image_scale,
        seed=campaign.seeds["navcheck"],
        progress=lambda done, total: tick("stereo pairs", done, total),
    )
    say("finding visual loop closures on navcheck (SIFT, stereo, candidates, registration)")
    vision = run_loop_stage(navcheck, progress=tick)
    loops = navcheck / "products" / "vision" / "loops.csv"
    say("SLAM on navcheck (DVL, compass, depth, GPS and visual loop closures in one GTSAM graph)")
    slam = run_slam(navcheck, loops=loops)
    say("checking pressure depth against the loop closures' vertical (tide given, and estimated)")
    depth = depth_products(
        navcheck, tide_path=navcheck / "truth" / "tide.csv", loops_path=loops, estimate=True, overwrite=True
    )
    dives["navcheck"]["evaluation"] = evaluate_dive(navcheck)

    correction = out / "compass-correction.yaml"
    say(f"fitting the compass correction on navcheck ({COMPASS_REFERENCE} headings), constant from transit")
    compass = run_compass_fit(
        [out / "navcheck"],
        reference=COMPASS_REFERENCE,
        transits=[out / "transit"],
        out=correction,
        overwrite=True,
    )
    say("simulating survey-corrected (the vehicle flies with the correction)")
    survey = out / "survey-corrected"
    sim = _simulate(
        out,
        survey.name,
        "survey",
        campaign.survey,
        campaign.seeds["survey"],
        compass_correction=correction,
        truth_loops=True,
    )
    say("navigating survey-corrected")
    nav = run_navigation(survey, compass_correction=correction)
    say("checking pressure depth against the survey's loop closures")
    depth_survey = depth_products(
        survey,
        tide_path=survey / "truth" / "tide.csv",
        loops_path=survey / "truth" / "loops.csv",
        overwrite=True,
    )
    dives[survey.name] = {
        "simulation": sim,
        "navigation": nav,
        "evaluation": evaluate_dive(survey, compass_correction=correction),
    }
    compass["evaluation"] = dives["survey-corrected"]["evaluation"].get("compass")

    summary = {
        "out": str(out),
        "quick": quick,
        "dives": dives,
        "compass": compass,
        "compass_reference": COMPASS_REFERENCE,
        "vision": vision,
        "slam": slam,
        "depth": {"navcheck": depth, "survey-corrected": depth_survey},
        "headline": _headline(dives),
        "not_yet_built": list(NOT_YET),
    }
    write_json(summary, out / "summary.json")
    return summary


def _headline(dives: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The figures the paper reports, measured on this campaign."""
    out: dict[str, Any] = {}
    for name, d in dives.items():
        sim, ev = d["simulation"], d["evaluation"]
        out[name] = {
            "distance_m": ev["distance_m"],
            "onboard_end_error_m": sim.get("end_error_m"),
            "dr_end_error_m": ev.get("dr", {}).get("end_error_m"),
            "dr_end_error_pct": ev.get("dr", {}).get("end_error_pct"),
            "filter_end_error_m": ev.get("filter", {}).get("end_error_m"),
            "filter_ate_aligned_rmse_m": ev.get("filter", {}).get("ate_aligned_rmse_m"),
            "slam_ate_aligned_rmse_m": ev.get("slam", {}).get("ate_aligned_rmse_m"),
        }
    return out


def format_demo(summary: dict[str, Any]) -> str:
    """The human account of :func:`run_demo`."""

    def cell(value: Any, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    lines = [
        f"auvnav demo ({'quick' if summary['quick'] else 'full'} campaign) in {summary['out']}",
        "",
        f"{'dive':<22}{'distance m':>12}{'onboard end m':>15}{'DR end m':>10}{'DR end %':>10}{'filter end m':>14}",
    ]
    for name, h in summary["headline"].items():
        lines.append(
            f"{name:<22}{cell(h['distance_m'], '.0f'):>12}{cell(h['onboard_end_error_m'], '.2f'):>15}"
            f"{cell(h['dr_end_error_m'], '.2f'):>10}{cell(h['dr_end_error_pct'], '.2f'):>10}"
            f"{cell(h['filter_end_error_m'], '.2f'):>14}"
        )
    lines += [
        "",
        "onboard end m: where the vehicle thought it surfaced minus where it did (its real-time navigation);",
        "DR/filter end m: post-processed dead reckoning and GPS-aided smoother against the truth.",
    ]
    nc = summary["dives"]["navcheck"]["evaluation"]
    lines += [
        "",
        "navcheck consistency (ATE after the best rigid alignment, the paper's point):",
        f"  dead reckoning {cell(nc.get('dr', {}).get('ate_aligned_rmse_m'), '.3f')} m, "
        f"filter {cell(nc.get('filter', {}).get('ate_aligned_rmse_m'), '.3f')} m, "
        f"SLAM {cell(nc.get('slam', {}).get('ate_aligned_rmse_m'), '.3f')} m",
    ]
    lo = nc.get("loops") or {}
    lines += [
        f"navcheck visual loop closures: {summary['vision']['nonconsecutive_accepted']} from "
        f"{summary['vision']['candidates_tested']} pairs tested ({summary['vision']['pairs_per_s']:.1f} "
        f"stereo pairs/s); recall {cell(lo.get('recall'), '.3f')}, precision {cell(lo.get('precision'), '.3f')}, "
        f"median error {cell(1000 * lo['translation_error_median_m'] if lo else None, '.1f')} mm / "
        f"{cell(lo.get('rotation_error_median_deg'), '.3f')} deg, mean Mahalanobis "
        f"{cell(lo.get('mahalanobis_mean'), '.1f')} (6 when honest)",
        "",
        "depth check: pressure-depth change minus loop-closure vertical change, RMS before / after tide",
    ]
    for name in ("navcheck", "survey-corrected"):
        d = summary["dives"][name]["evaluation"].get("depth") or {}
        lines.append(
            f"  {name:<17} all loops {cell(d.get('residual_rms_before_m'), '.3f')} / "
            f"{cell(d.get('residual_rms_after_m'), '.3f')} m; over 20 min apart "
            f"{cell(d.get('far_apart_residual_rms_before_m'), '.3f')} / "
            f"{cell(d.get('far_apart_residual_rms_after_m'), '.3f')} m"
        )
    ev = summary["compass"].get("evaluation") or {}
    lines += [
        "",
        f"compass correction ({summary['compass_reference']} headings on navcheck, constant from GPS transits):",
        f"  against the true deviation: RMS {cell(ev.get('deviation_rmse_deg'), '.3f')} deg, "
        f"max {cell(ev.get('deviation_max_error_deg'), '.3f')} deg; shape only RMS "
        f"{cell(ev.get('shape_rmse_deg'), '.3f')} deg; constant error {cell(ev.get('constant_error_deg'), '+.3f')} deg",
    ]
    if summary["not_yet_built"]:
        lines += ["", "not run (not built yet):", *[f"  - {s}" for s in summary["not_yet_built"]]]
    return "\n".join(lines)
