"""``auvnav demo``: the paper's experiment on a built-in simulated campaign.

The campaign mirrors the Scott Reef cruise of the paper (section IV): a navigation check dive (star of
reciprocal legs plus a grid, section III-A), long sub-sea transits between GPS fixes (for the compass
correction's constant, Fig. 5b), and the 75 m x 50 m full-coverage survey (section IV-A) flown three
ways: with the vehicle's compass as it is, with the deviation removed (the best the DVL allows), and with
the correction fitted from the check dive. Each dive is simulated, then processed as a user's dive would
be (:func:`auvnav.pipeline.process`), then the compass correction is fitted across dives (the shape on
the check dive, the constant on the transits); every figure is measured against the simulator's truth,
and the summary says which stages do not exist yet rather than pretending they ran.
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


def _process(
    dive: Path, say: Progress, tick: Callable[[str, int, int], None], **settings: Any
) -> dict[str, Any]:
    """``auvnav process`` on a dive of the campaign; each stage's summary by name (raises on a failure)."""
    from auvnav.errors import AuvnavError
    from auvnav.pipeline import process

    result = process(dive, settings=settings, say=lambda line: say(f"  {line}"), progress=tick)
    if result.failed:
        first = result.failed[0]
        raise AuvnavError(f"{dive}: stage {first.stage} failed: {first.reason}")
    return {o.stage: o.summary for o in result.outcomes if o.summary is not None}


#: Where the compass fit takes its reference headings: SLAM, as in the paper.
COMPASS_REFERENCE = "slam"


def run_demo(
    out: Path, *, quick: bool = False, overwrite: bool = False, progress: Progress | None = None
) -> dict[str, Any]:
    """Simulate the campaign into ``out``, process every dive, fit the compass; return the measurements.

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
    from auvnav.compass.evaluate import TRUE_DEVIATION_FILE, read_true_deviation
    from auvnav.compass.stage import CompassSettings, fit_to_file
    from auvnav.depth.stage import DepthSettings
    from auvnav.evaluate import evaluate_dive
    from auvnav.executor import make_executor
    from auvnav.nav.stage import NavSettings
    from auvnav.report.compass_figures import CorrectionFigure, plot_correction
    from auvnav.sim.camera import render_dive_images
    from auvnav.slam.stage import SlamSettings

    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda text: log.info(text))
    tick = _throttled(say)
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
        dives[name] = {"simulation": _simulate(out, name, scenario, geometry, seed, **options)}

    navcheck = out / "navcheck"
    say(f"rendering navcheck's stereo images ({campaign.image_scale:g} scale)")
    with make_executor() as executor:
        render_dive_images(
            navcheck,
            scale=campaign.image_scale,
            seed=campaign.seeds["navcheck"],
            executor=executor,
            progress=lambda done, total: tick("stereo pairs", done, total),
        )
    say("processing navcheck (navigation, visual loop closures, SLAM, compass, depth against the tide)")
    navcheck_stages = _process(
        navcheck, say, tick, depth=DepthSettings(tide=navcheck / "truth" / "tide.csv", estimate_tide=True)
    )
    dives["navcheck"].update(navigation=navcheck_stages["nav"], evaluation=evaluate_dive(navcheck))
    for name, *_ in plan[1:]:
        say(f"processing {name} (navigation)")
        stages = _process(out / name, say, tick)
        dives[name].update(navigation=stages["nav"], evaluation=evaluate_dive(out / name))

    correction = out / "compass-correction.yaml"
    say(f"fitting the compass correction on navcheck ({COMPASS_REFERENCE} headings), constant from transit")
    fit = fit_to_file(
        [navcheck],
        CompassSettings(reference=COMPASS_REFERENCE, transits=(out / "transit",)),
        correction,
        overwrite=True,
    )
    truth = read_true_deviation(navcheck) if (navcheck / TRUE_DEVIATION_FILE).is_file() else None
    plot_correction(CorrectionFigure.from_fit(fit), correction.with_suffix(".png"), true_deviation=truth)
    compass = {"correction": str(correction), "figure": str(correction.with_suffix(".png")), **fit.summary()}

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
    say("processing survey-corrected (navigation with the correction; SLAM and depth check on its loops)")
    loops, tide = survey / "truth" / "loops.csv", survey / "truth" / "tide.csv"
    stages = _process(
        survey,
        say,
        tick,
        nav=NavSettings(compass_correction=correction),
        slam=SlamSettings(loops=loops, compass_correction=correction),
        depth=DepthSettings(loops=loops, tide=tide),
    )
    dives[survey.name] = {
        "simulation": sim,
        "navigation": stages["nav"],
        "evaluation": evaluate_dive(survey, compass_correction=correction),
    }
    compass["evaluation"] = dives["survey-corrected"]["evaluation"].get("compass")

    summary = {
        "out": str(out),
        "quick": quick,
        "dives": dives,
        "compass": compass,
        "compass_reference": COMPASS_REFERENCE,
        "vision": navcheck_stages["vision"],
        "slam": navcheck_stages["slam"],
        "depth": {"navcheck": navcheck_stages["depth"], "survey-corrected": stages["depth"]},
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
