"""Benchmark of the compass issue end to end on default-size simulated scenarios (issue 5).

The chain, every dive with the default deviation unless said otherwise:

1. ``navcheck`` (seed 1) -> ``compass fit --reference truth``: the deviation's shape against the true
   curve (``truth/deviation.csv``), constant excluded: RMS and maximum error over 360 degrees
   (target: RMS at most 0.1 degree);
2. ``transit`` (default 4 x 2 km, seed 2) -> ``--transits``: the constant from GPS course made good
   with the shape held (target: within 0.2 degree of the true constant);
3. ``survey`` (seed 3) flown three ways: with the correction from 1-2 applied in real time, with
   ``--deviation none``, and uncorrected; the onboard-versus-true error at the last surfacing
   (target: corrected within 20% or 2 m, whichever is larger, of the no-deviation survey, and far
   below the uncorrected one). The survey is also flown with the truth-constant correction of 1;
4. ``spin`` (seed 4) -> ``compass calibrate``: hard iron against the injected one (target: 1% of
   the field) and calibrated heading against the truth, RMS about its constant offset (target:
   0.3 degree).

Dives are simulated into ``--out`` (kept for inspection; reused with ``--reuse``). The results
table is printed at the end.

Run: ``.venv/bin/python benchmarks/bench_compass.py [--out DIR] [--reuse]``
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

from auvnav.compass.calibrate import calibrate_dive
from auvnav.compass.evaluate import compass_section
from auvnav.report.compass_figures import run_compass_fit
from auvnav.sim.run import run_scenario

SHAPE_RMS_TARGET_DEG = 0.1
CONSTANT_TARGET_DEG = 0.2
LOOP_TARGET_FRACTION, LOOP_TARGET_M = 0.2, 2.0
HARD_IRON_TARGET_PCT = 1.0
HEADING_TARGET_DEG = 0.3


def simulate(out: Path, scenario: str, seed: int, reuse: bool, **options: Any) -> dict[str, Any]:
    """Simulate a scenario into ``out`` (or reuse it); its summary with the wall time."""
    if reuse and (out / "truth" / "truth.yaml").is_file():
        import yaml

        summary = yaml.safe_load((out / "truth" / "truth.yaml").read_text())["result"]
        return {**summary, "wall_s": 0.0}
    start = time.perf_counter()
    summary = run_scenario(scenario, out, seed=seed, overwrite=True, **options)
    return {**summary, "wall_s": time.perf_counter() - start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/auvnav-bench-compass"))
    parser.add_argument("--reuse", action="store_true", help="Reuse dives already simulated in --out.")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, str, str]] = []

    navcheck, transit = out / "navcheck", out / "transit"
    sims = {
        "navcheck": simulate(navcheck, "navcheck", 1, args.reuse),
        "transit": simulate(transit, "transit", 2, args.reuse),
    }
    start = time.perf_counter()
    shape = run_compass_fit([navcheck], reference="truth", out=out / "fit_truth.yaml", overwrite=True)
    full = run_compass_fit(
        [navcheck], reference="truth", transits=[transit], out=out / "fit_transits.yaml", overwrite=True
    )
    fit_s = time.perf_counter() - start
    shape_score = compass_section(navcheck, out / "fit_truth.yaml")
    full_score = compass_section(navcheck, out / "fit_transits.yaml")
    rows += [
        ("heading pairs (navcheck, 1 Hz)", f"{shape['pairs']['used']} of {shape['pairs']['candidates']}", ""),
        (
            "shape RMS error, constant excluded",
            f"{shape_score['shape_rmse_deg']:.4f} deg",
            f"<= {SHAPE_RMS_TARGET_DEG} deg: {'yes' if shape_score['shape_rmse_deg'] <= SHAPE_RMS_TARGET_DEG else 'NO'}",
        ),
        ("shape max error, constant excluded", f"{shape_score['shape_max_error_deg']:.4f} deg", ""),
        ("constant error, truth reference", f"{shape_score['constant_error_deg']:+.4f} deg", ""),
        (
            "constant error, GPS transits",
            f"{full_score['constant_error_deg']:+.4f} deg "
            f"(+- {full['constant']['sigma_deg']:.3f}, {full['constant']['legs']} legs)",
            f"within {CONSTANT_TARGET_DEG} deg: "
            f"{'yes' if abs(full_score['constant_error_deg']) <= CONSTANT_TARGET_DEG else 'NO'}",
        ),
        (
            "deviation RMS / max error, transit constant",
            f"{full_score['deviation_rmse_deg']:.4f} / {full_score['deviation_max_error_deg']:.4f} deg",
            "",
        ),
        ("fit wall time (both fits)", f"{fit_s:.1f} s", ""),
    ]
    for leg in full["legs"]:
        rows.append(
            (
                f"  transit leg at {leg['heading_deg']:.1f} deg",
                f"{leg['length_m']:.0f} m, CMG - DR {leg['course_error_deg']:+.3f} +- "
                f"{leg['course_sigma_deg']:.3f} deg, residual {leg['residual_deg']:+.3f} deg",
                "used" if leg["used"] else leg["reason"],
            )
        )

    surveys: list[tuple[str, str, dict[str, Any]]] = [
        (
            "corrected (transit constant)",
            "survey_corrected",
            {"compass_correction": out / "fit_transits.yaml"},
        ),
        (
            "corrected (truth constant)",
            "survey_corrected_truth",
            {"compass_correction": out / "fit_truth.yaml"},
        ),
        ("no deviation", "survey_no_deviation", {"deviation": "none"}),
        ("uncorrected", "survey_uncorrected", {}),
    ]
    ends = {}
    for label, folder, options in surveys:
        sims[label] = simulate(out / folder, "survey", 3, args.reuse, **options)
        ends[label] = sims[label]["end_error_m"]
    bound = max((1.0 + LOOP_TARGET_FRACTION) * ends["no deviation"], ends["no deviation"] + LOOP_TARGET_M)
    for label, end in ends.items():
        verdict = ""
        if label.startswith("corrected"):
            verdict = f"<= {bound:.2f} m: {'yes' if end <= bound else 'NO'}"
        rows.append((f"survey end error, {label}", f"{end:.2f} m", verdict))
    rows.append(("survey distance", f"{sims['no deviation']['horizontal_distance_m']:.0f} m", ""))

    spin = out / "spin"
    sims["spin"] = simulate(spin, "spin", 4, args.reuse)
    for method in ("levelled", "ellipsoid"):
        cal = calibrate_dive(spin, method=method)
        truth = cal["truth"]
        errors = truth["hard_iron_error_pct"]
        worst = max(abs(v) for v in errors if v is not None)
        rows += [
            (
                f"spin {method}: hard-iron error (x, y, z)",
                ", ".join("n/a" if v is None else f"{v:+.3f}%" for v in errors) + " of the field",
                f"<= {HARD_IRON_TARGET_PCT}%: {'yes' if worst <= HARD_IRON_TARGET_PCT else 'NO'}",
            ),
            (
                f"spin {method}: heading RMS about offset",
                f"{truth['heading_rms_deg']:.3f} deg (offset {truth['heading_offset_deg']:+.3f} deg; "
                f"raw compass {truth['compass_rms_deg']:.3f} deg RMS)",
                f"<= {HEADING_TARGET_DEG} deg: {'yes' if truth['heading_rms_deg'] <= HEADING_TARGET_DEG else 'NO'}",
            ),
            (
                f"spin {method}: field spread",
                f"{cal['field_spread_before_pct']:.2f}% -> {cal['field_spread_after_pct']:.3f}%",
                "",
            ),
        ]
    for name, s in sims.items():
        rows.append(
            (
                f"simulated {name}",
                f"{s['duration_s'] / 3600:.2f} h of vehicle time in {s['wall_s']:.0f} s",
                "",
            )
        )

    width = max(len(r[0]) for r in rows)
    value_width = max(len(r[1]) for r in rows)
    print(f"{'measure':<{width}}  {'value':<{value_width}}  target")
    for name, value, target in rows:
        print(f"{name:<{width}}  {value:<{value_width}}  {target}")


if __name__ == "__main__":
    main()
