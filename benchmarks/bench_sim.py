"""Benchmark of the simulator: the default survey with and without the compass deviation.

Issue 3's targets and measurements:

- speed: simulating the default survey (75 m x 50 m at 1 m after a 100 m lead-in, about 2.5 h of
  vehicle time) without images in under 60 s; the time of :func:`auvnav.sim.run.simulate` is
  reported (writing the folder is timed separately);
- the paper's effect (section IV-A, Fig. 8 and 9: about 90 m against about 10 m after 5 km): the
  distance between the onboard and the true position when the vehicle surfaces, with the default
  deviation and no correction against the same survey with the deviation removed, and how the
  spacing between adjacent reciprocal lines departs from the planned 1 m (mean, min, max over
  stations every metre along the middle of every line, 10 m left out at each end).

Run: ``.venv/bin/python benchmarks/bench_sim.py [--seed 0] [--figure tracks.png] [--out DIR]``
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np

from auvnav.plan.missions import survey, survey_line_spacing
from auvnav.report.figures import plot_tracks
from auvnav.sim.run import default_config, simulate, write_simulation

TARGET_S = 60.0


def run(seed: int, deviation: str, out: Path | None, figure: Path | None) -> dict[str, float]:
    mission = survey()
    start = time.perf_counter()
    sim = simulate(mission, default_config(seed=seed, deviation=deviation))  # type: ignore[arg-type]
    elapsed = time.perf_counter() - start
    folder = out / f"survey_{deviation}" if out is not None else Path(tempfile.mkdtemp()) / "dive"
    start = time.perf_counter()
    write_simulation(sim, folder, overwrite=True)
    written = time.perf_counter() - start
    spacing = survey_line_spacing(sim.trajectory.p_ned_m[:, :2], sim.onboard.p_ned_m[:, :2], mission)
    onboard = survey_line_spacing(sim.onboard.p_ned_m[:, :2], sim.onboard.p_ned_m[:, :2], mission)
    if figure is not None:
        path = figure.with_name(f"{figure.stem}_{deviation}{figure.suffix}")
        plot_tracks(
            [("true", sim.trajectory), ("onboard", sim.onboard)],
            path,
            title=f"default survey, deviation {deviation}: true and onboard tracks",
        )
    s = sim.summary
    return {
        "simulate_s": elapsed,
        "write_s": written,
        "vehicle_time_h": s["duration_s"] / 3600,
        "distance_m": s["horizontal_distance_m"],
        "end_error_m": s["end_error_m"],
        "spacing_mean_m": float(np.nanmean(spacing)),
        "spacing_min_m": float(np.nanmin(spacing)),
        "spacing_max_m": float(np.nanmax(spacing)),
        "onboard_spacing_mean_m": float(np.nanmean(onboard)),
        "onboard_spacing_min_m": float(np.nanmin(onboard)),
        "onboard_spacing_max_m": float(np.nanmax(onboard)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--figure", type=Path, help="PNG of true vs onboard tracks (suffixed per run)")
    parser.add_argument("--out", type=Path, help="keep the dive folders here")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    results = {dev: run(args.seed, dev, args.out, args.figure) for dev in ("default", "none")}
    rows = list(results["default"])
    print(f"{'':28s} {'deviation default':>18s} {'deviation none':>18s}")
    for key in rows:
        print(f"{key:28s} {results['default'][key]:18.3f} {results['none'][key]:18.3f}")
    worst = max(r["simulate_s"] for r in results.values())
    print(
        f"simulate time {worst:.1f} s (target < {TARGET_S:.0f} s): {'PASS' if worst < TARGET_S else 'FAIL'}"
    )


if __name__ == "__main__":
    main()
