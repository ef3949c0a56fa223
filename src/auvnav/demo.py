"""``auvnav demo``: the paper's experiment on a built-in simulated campaign.

The campaign mirrors the Scott Reef cruise of the paper (section IV): a navigation check dive (star of
reciprocal legs plus a grid, section III-A), long sub-sea transits between GPS fixes (for the compass
correction's constant, Fig. 5b), and the 75 m x 50 m full-coverage survey (section IV-A) flown three
ways: with the vehicle's compass as it is, with the deviation removed (the best the DVL allows), and with
the correction fitted from the check dive. Each dive is simulated, then processed as a user's dive would
be (:func:`auvnav.pipeline.process`), then the compass correction is fitted across dives (the shape on
the check dive, the constant on the transits). Each survey is flown after the correction exists, and
before it is flown its coverage is predicted (:mod:`auvnav.coverage.predict`: the correction as the
compass's deviation for the uncorrected flight, applied for the corrected one, none without deviation);
its SLAM (on the simulator's truth loop closures, the correction applied in post-processing whether or
not the vehicle applied it) then gives its measured coverage. Every figure is
measured against the simulator's truth, and the summary says which stages do not exist yet rather than
pretending they ran.

The coverage adds about a minute to the quick demo and a few minutes to the full one: the uncorrected
and no-deviation surveys get truth loop closures and SLAM, and every survey its coverage stage,
prediction and evaluation.
"""

from __future__ import annotations

import dataclasses
import json
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
NOT_YET: tuple[str, ...] = ()


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
    recon_half_m: float = 6.0  # the reconstructed patch: the check dive's grid, +- this many metres


FULL = Campaign()
QUICK = Campaign(
    navcheck={"headings": 8, "leg_m": 20.0, "grid_m": 6.0},
    transit={"legs": 4, "leg_m": 400.0},
    survey={"width_m": 20.0, "height_m": 20.0, "lead_in_m": 20.0},
    image_scale=0.25,
    recon_half_m=4.0,
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


def _add_camera_calibration(dive: Path, like: Path) -> None:
    """Give a simulated dive whose images were not rendered the stereo calibration of ``like`` (its
    camera's trigger log exists; the vehicle still has its calibrated camera)."""
    from auvnav.vehicle import read_vehicle, write_vehicle

    path = dive / "vehicle.yaml"
    vehicle, rig = read_vehicle(path), read_vehicle(like / "vehicle.yaml").stereo
    if vehicle.stereo is None and rig is not None:
        write_vehicle(dataclasses.replace(vehicle, stereo=rig), path)


def _predict(mission: Path, navcheck: Path, correction: Path, options: dict[str, Any]) -> dict[str, Any]:
    """``auvnav coverage predict`` for a survey flown with ``options`` (the simulator's), from what is
    known before it: the mission, the vehicle's camera (the check dive's), the correction fitted on the
    check dive (the compass's deviation as estimated) and the site's declination."""
    import math

    from auvnav.compass.correction import read_correction
    from auvnav.coverage.plan import survey_plan
    from auvnav.coverage.predict import FootprintExtent, HeadingErrorPrior, predict_survey
    from auvnav.dive import read_dive_info
    from auvnav.plan.missions import read_mission
    from auvnav.vehicle import read_vehicle

    planned = read_mission(mission)
    if options.get("deviation") == "none":
        prior = HeadingErrorPrior.deviation_peak(0.0, source="no deviation")
    else:
        applied = "compass_correction" in options
        prior = HeadingErrorPrior.from_correction(
            read_correction(correction), applied=applied, source=correction.name
        )
    footprint = FootprintExtent.of_vehicle(read_vehicle(navcheck / "vehicle.yaml"), planned.altitude_m)
    declination = read_dive_info(navcheck).declination_rad
    prediction = predict_survey(
        survey_plan(planned), prior, footprint, declination_rad=0.0 if declination is None else declination
    )
    summary = prediction.summary()
    summary.pop("pairs")
    summary["declination_deg"] = math.degrees(declination or 0.0)
    return summary


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
    from auvnav.recon.stage import ReconSettings
    from auvnav.report.compass_figures import CorrectionFigure, plot_correction
    from auvnav.sim.camera import render_dive_images

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
    say(
        "processing navcheck (navigation, visual loop closures, SLAM, compass, depth against the tide, "
        "reconstruction of its grid)"
    )
    h = campaign.recon_half_m
    navcheck_stages = _process(
        navcheck,
        say,
        tick,
        depth=DepthSettings(tide=navcheck / "truth" / "tide.csv", estimate_tide=True),
        recon=ReconSettings(north_min_m=-h, north_max_m=h, east_min_m=-h, east_max_m=h),
    )
    dives["navcheck"].update(navigation=navcheck_stages["nav"], evaluation=evaluate_dive(navcheck))
    say("reconstructing the same pairs of navcheck's grid with dead reckoning")
    recon = {
        "slam": {
            "summary": navcheck_stages.get("recon"),
            "evaluation": dives["navcheck"]["evaluation"].get("recon"),
        },
        "dr": _recon_with(navcheck, "dr", out / "navcheck-recon-dr", tick),
    }
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

    survey_dives, depth_stages = _fly_surveys(out, campaign, correction, navcheck, say, tick)
    dives.update(survey_dives)
    compass["evaluation"] = dives["survey-corrected"]["evaluation"].get("compass")

    summary = {
        "out": str(out),
        "quick": quick,
        "dives": dives,
        "compass": compass,
        "compass_reference": COMPASS_REFERENCE,
        "vision": navcheck_stages["vision"],
        "slam": navcheck_stages["slam"],
        "depth": {"navcheck": navcheck_stages["depth"], "survey-corrected": depth_stages},
        "recon": recon,
        "headline": _headline(dives),
        "not_yet_built": list(NOT_YET),
    }
    write_json(summary, out / "summary.json")
    say("writing the campaign's report (one HTML page: every dive, its figures, map and 3D view)")
    from auvnav.report.campaign import build_campaign_report

    report = build_campaign_report(out)  # reads summary.json: the scores against the truth
    summary["report"] = {k: report[k] for k in ("page", "page_bytes", "seconds")}
    write_json(summary, out / "summary.json")
    return summary


def _fly_surveys(
    out: Path,
    campaign: Campaign,
    correction: Path,
    navcheck: Path,
    say: Progress,
    tick: Callable[[str, int, int], None],
) -> tuple[dict[str, dict[str, Any]], dict[str, Any] | None]:
    """The survey flown three ways (the raw compass, the correction applied in real time, no
    deviation), each predicted before it is flown (:func:`_predict`), then simulated with truth loop
    closures, processed (the correction applied in post-processing to both deviating ones; SLAM on the
    truth loops; coverage against the mission) and evaluated. Returns each dive's record by name and
    the corrected survey's depth check."""
    from auvnav.coverage.stage import CoverageSettings
    from auvnav.depth.stage import DepthSettings
    from auvnav.evaluate import evaluate_dive
    from auvnav.nav.stage import NavSettings
    from auvnav.plan.missions import survey, write_mission
    from auvnav.slam.stage import SlamSettings

    dives: dict[str, dict[str, Any]] = {}
    mission = out / "survey.yaml"
    write_mission(survey(**campaign.survey), mission)
    surveys = [
        (
            "survey-uncorrected",
            "raw compass",
            {},
            {
                "nav": NavSettings(compass_correction=correction),
                "slam": SlamSettings(compass_correction=correction),
            },
        ),
        (
            "survey-corrected",
            "with the correction",
            {"compass_correction": correction},
            {
                "nav": NavSettings(compass_correction=correction),
                "slam": SlamSettings(compass_correction=correction),
                "depth": DepthSettings(),
            },
        ),
        ("survey-no-deviation", "no deviation", {"deviation": "none"}, {"slam": SlamSettings()}),
    ]
    depth_stages = None
    for name, flown, options, settings in surveys:
        survey_dive = out / name
        say(f"predicting {name}'s coverage before it is flown ({flown})")
        prediction = _predict(mission, navcheck, correction, options)
        say(f"simulating {name} with truth loop closures")
        sim = _simulate(
            out, name, "survey", campaign.survey, campaign.seeds["survey"], truth_loops=True, **options
        )
        _add_camera_calibration(survey_dive, navcheck)
        loops, tide = survey_dive / "truth" / "loops.csv", survey_dive / "truth" / "tide.csv"
        settings["slam"] = dataclasses.replace(settings["slam"], loops=loops)
        if "depth" in settings:
            settings["depth"] = DepthSettings(loops=loops, tide=tide)
        say(f"processing {name} (navigation; SLAM on its loops; coverage from SLAM)")
        stages = _process(survey_dive, say, tick, coverage=CoverageSettings(mission=mission), **settings)
        dives[name] = {
            "simulation": sim,
            "navigation": stages["nav"],
            "prediction": prediction,
            "coverage": stages.get("coverage"),
            "evaluation": evaluate_dive(
                survey_dive, compass_correction=correction if "compass_correction" in options else None
            ),
        }
        if "depth" in settings:
            depth_stages = stages.get("depth")
    return dives, depth_stages


def _recon_with(
    dive: Path, trajectory: str, folder: Path, tick: Callable[[str, int, int], None]
) -> dict[str, Any]:
    """The pairs the dive's reconstruction used, placed with another trajectory into ``folder`` (its
    dense maps come from the stage's cache), and scored against the truth."""
    import shutil

    import pandas as pd

    from auvnav import products as P
    from auvnav.dive import read_dive
    from auvnav.evaluate import evaluate_recon
    from auvnav.executor import make_executor
    from auvnav.recon.reconstruct import ReconInputs, reconstruct
    from auvnav.recon.stage import TRAJECTORIES, ReconSettings, pressure_file
    from auvnav.trajectory import read_trajectory

    pairs_file = P.RECON_PAIRS.path(dive)
    if not pairs_file.is_file():
        return {"summary": None, "evaluation": None}
    record = P.read_record(dive, "recon") or {}
    settings = ReconSettings(**{k: v for k, v in (record.get("settings_given") or {}).items() if k != "tide"})
    base = json.loads(P.RECON_SUMMARY.path(dive).read_text(encoding="utf-8"))
    tide_source = (base.get("tide") or {}).get("source")
    tide = None
    if tide_source:
        from auvnav.depth.tide import read_constituents
        from auvnav.dive import read_dive_info

        path = Path(tide_source.rsplit(" (", 1)[0])
        tide = read_constituents(path, latitude_rad=read_dive_info(dive).origin.latitude_rad)
    pressure = pressure_file(dive)
    inputs = ReconInputs(
        trajectory=read_trajectory(TRAJECTORIES[trajectory].path(dive)),
        trajectory_name=trajectory,
        tide=tide,
        tide_source=tide_source,
        apply_tide=True,
        pressure_track=None if pressure is None else read_trajectory(pressure),
    )
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    pairs = pd.read_csv(pairs_file)
    with make_executor() as executor:
        summary = reconstruct(
            read_dive(dive),
            inputs,
            folder,
            dense=settings.dense(),
            fusion=settings.fusion(),
            pairs=pairs.loc[pairs["status"] == "ok", "i"].to_numpy(),
            cache_dir=P.cache_dir(dive, "recon") / "dense",
            executor=executor,
            progress=tick,
        )
    write_json(summary, folder / "summary.json")
    return {"summary": summary, "evaluation": evaluate_recon(dive, folder=folder)}


def _format_recon(summary: dict[str, Any]) -> list[str]:
    """The check dive's grid reconstructed with SLAM and with dead reckoning."""
    recon = summary.get("recon") or {}
    slam = recon.get("slam") or {}
    if not slam.get("summary") or not slam.get("evaluation"):
        return []
    s = slam["summary"]
    out = [
        "",
        f"reconstruction of navcheck's grid ({s['pairs']['used']} stereo pairs at {s['dense']['width_px']} px, "
        f"DEM {s['dem']['area_m2']:.0f} m^2 at {100 * s['fusion']['dem_cell_m']:.0f} cm, orthophoto at "
        f"{1000 * s['fusion']['mosaic_cell_m']:.0f} mm; {s['seconds']['total']:.0f} s, {s['pairs_per_s']:.1f} pairs/s):",
    ]
    for name, title in (("slam", "SLAM"), ("dr", "dead reckoning")):
        ev = (recon.get(name) or {}).get("evaluation")
        if not ev:
            continue

        def mm(x: Any) -> str:
            return "-" if x is None else f"{1000 * x:.1f} mm"

        out.append(
            f"  {title:<15} DEM RMSE {mm(ev.get('dem_rmse_m'))}; orthophoto misregistration median "
            f"{ev.get('mosaic_misregistration_median_px') or float('nan'):.2f} px, 95th percentile "
            f"{ev.get('mosaic_misregistration_p95_px') or float('nan'):.2f} px"
        )
    ev = slam["evaluation"]
    if ev.get("relief_step_before_m") is not None:
        after = ev.get("relief_step_after_m")
        out.append(
            f"  false relief on revisits over 20 min apart, placed with pressure depth: steps "
            f"{100 * ev['relief_step_before_m']:.1f} cm RMS before the tide correction, "
            + ("-" if after is None else f"{100 * after:.1f} cm after")
            + f" ({ev.get('relief_comparisons', 0)} revisits); with SLAM as solved "
            f"{100 * (s['relief']['step_placed_rms_m'] or 0):.1f} cm"
        )
    return out


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
            "coverage_pct": ev.get("coverage", {}).get("coverage_pct"),
            "coverage_pct_true": ev.get("coverage", {}).get("coverage_pct_true"),
            "coverage_pct_predicted": (d.get("prediction") or {}).get("coverage_pct_mean"),
        }
    return out


def _format_coverage(summary: dict[str, Any]) -> list[str]:
    """The surveys' coverage: predicted before each flight, measured from the products (SLAM), and the
    truth."""

    def f(x: Any, fmt: str = ".2f", scale: float = 1.0) -> str:
        return "-" if x is None else f"{scale * x:{fmt}}"

    out = []
    for name, d in summary["dives"].items():
        p, c, ev = d.get("prediction"), d.get("coverage"), d.get("evaluation", {}).get("coverage")
        if p is None or c is None:
            continue
        if not out:
            plan = c.get("plan") or {}
            out += [
                "",
                f"survey coverage ({f(plan.get('area_m2'), '.0f')} m^2 planned, lines "
                f"{f(c['lines']['planned_spacing_m'])} m apart, stereo footprint "
                f"{f(p['footprint_width_m'])} m wide): predicted before the flight / measured / truth",
            ]
        sp, ln, g = p["spacing"], c["lines"], c["gaps"]
        out.append(
            f"  {name:<20} predicted: spacing {f(sp['mean_m'])} m (largest {f(sp['max_m'])} m), "
            f"P(gap >= {f(p['gap_width_m'])} m) {f(p['p_gap'])}, coverage {f(p['coverage_pct_mean'], '.1f')}%"
        )
        out.append(
            f"  {'':<20} {c.get('trajectory', '?')}: coverage {f(c['coverage_pct'], '.1f')}%, gaps "
            f"{f(g['area_m2'], '.1f')} m^2 ({g['count_wider']} at least {f(g['wider_than_m'])} m wide), spacing "
            f"{f(ln['spacing_min_m'])}-{f(ln['spacing_max_m'])} m; pairs on plan {ln['on_plan']}, "
            f"accordion {ln['accordion']}, figure 8 {ln['figure_8']}"
        )
        if ev:
            out.append(
                f"  {'':<20} truth: coverage {f(ev['coverage_pct_true'], '.1f')}%, gaps "
                f"{f(ev['gap_area_true_m2'], '.1f')} m^2, spacing {f(ev['spacing_true_min_m'])}-"
                f"{f(ev['spacing_true_max_m'])} m; measured spacing RMSE {f(ev['spacing_rmse_m'], '.1f', 100)} cm"
            )
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
    lines += _format_coverage(summary)
    lines += _format_recon(summary)
    if summary["not_yet_built"]:
        lines += ["", "not run (not built yet):", *[f"  - {s}" for s in summary["not_yet_built"]]]
    report = summary.get("report")
    if report:
        lines += [
            "",
            f"report: {report['page']} ({report['page_bytes'] / 1e6:.1f} MB, one self-contained page: open it "
            "in a browser, no network needed)",
        ]
    return "\n".join(lines)
