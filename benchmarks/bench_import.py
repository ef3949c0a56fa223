"""Benchmark of the importers and of the raw-sample magnetometer calibration (issue 15).

Measured, with the commands that measure them:

- ``auvnav import acfr-raw`` of a 6-hour ACFR log (target < 30 s): a 6-hour transit is simulated
  (no images), written as ``combined.RAW.auv`` + ``mission.cfg`` by the tests' independent writer
  (``tests/io/io_writers.py``), imported by the command line (wall time, a fresh process), and both
  dives navigated: their end errors must agree within 1 mm;
- ``auvnav import rosbag`` of a 1 GB ROS 1 bag and a 1 GB ROS 2 bag (the same dive's navigation
  messages plus stereo pairs of incompressible 256 KiB CompressedImage payloads): wall time and the
  peak resident memory of the importing process (goal < 1 GB), against the same bags with only
  their first few images (the baseline of a bag of navigation only);
- raw magnetometer samples of a vehicle that never pitches or rolls more than 10 degrees (a
  tilted-plane, partial-coverage set; the simulator's site and a default-like hard and soft iron;
  0.1% magnetometer noise, 0.05 degree inclinometer noise; five seeds): from the samples alone the
  fit is refused (its message), and with pitch, roll and the field model the calibrated
  field-magnitude spread and the hard-iron error against the truth; the same for +-40 degrees;
- IGRF-14 against the IAGA reference implementation's published values (BGS pyIGRF): the largest
  declination difference.

Run: ``.venv/bin/python benchmarks/bench_import.py [--work DIR] [--hours 6] [--bag-gb 1.0] [--skip-bag]``
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "io"))  # the independent format writers

from io_writers import write_acfr, write_bag  # noqa: E402

from auvnav import products as P  # noqa: E402
from auvnav.dive import ImageIndex, read_dive  # noqa: E402
from auvnav.pipeline import run_stage  # noqa: E402
from auvnav.trajectory import read_trajectory  # noqa: E402

AUVNAV = str(Path(sys.executable).with_name("auvnav"))
TARGET_ACFR_S = 30.0
TARGET_RSS_MB = 1024.0


def _end_errors(path: Path, truth: Path) -> dict[str, float]:
    run_stage(path, "nav")
    t = read_trajectory(truth / "trajectory.csv")
    out = {}
    for name, product in (("dr", P.NAV_DR), ("filter", P.NAV_FILTER)):
        track = read_trajectory(product.path(path))
        out[name] = float(np.linalg.norm(track.p_ned_m[-1] - t.interpolate(track.t_s[-1:]).p_ned_m[0]))
    return out


def _timed_import(args: list[str]) -> tuple[float, float, dict]:
    """Run ``auvnav import ...`` in a fresh process: wall seconds, its peak RSS (MB), its summary."""
    probe = (
        "import resource, subprocess, sys, time\n"
        "t = time.perf_counter()\n"
        "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
        "dt = time.perf_counter() - t\n"
        "rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024\n"
        "sys.stderr.write(p.stderr)\n"
        "print(dt, rss, p.returncode)\n"
        "print(p.stdout)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe, AUVNAV, "import", *args, "--json", "-q"], capture_output=True, text=True
    )
    first, _, rest = done.stdout.partition("\n")
    seconds, rss, code = first.split()
    if int(code) != 0:
        raise RuntimeError(f"auvnav import failed: {done.stderr.strip()}")
    return float(seconds), float(rss), json.loads(rest)


def bench_acfr(work: Path, hours: float) -> tuple[dict, Path]:
    from auvnav.sim.run import run_scenario

    dive = work / "long"
    if not dive.exists():
        legs = 6
        leg_m = hours * 3600 * 0.5 / legs * 0.93  # ~0.5 m/s, with descents, turns and surfacing
        start = time.perf_counter()
        run_scenario("transit", dive, seed=7, geometry={"legs": legs, "leg_m": leg_m}, usbl=True)
        print(f"simulated the long dive in {time.perf_counter() - start:.0f} s")
    d = _with_camera(read_dive(dive))
    t0, t1 = d.time_span_s()
    start = time.perf_counter()
    raw, cfg = write_acfr(d, work / "acfr")
    written = time.perf_counter() - start
    settings = work / "acfr.yaml"
    settings.write_text(f"vehicle: {dive / 'vehicle.yaml'}\n")
    out = work / "long_acfr"
    seconds, rss, summary = _timed_import(
        ["acfr-raw", str(raw), str(cfg), "--out", str(out), "--config", str(settings), "--overwrite"]
    )
    original = _end_errors(dive, dive / "truth")
    imported = _end_errors(out, dive / "truth")
    lines = sum(
        summary["read"].get(f"{k} lines", 0)
        for k in ("RDI", "PHINS_COMPASS", "PAROSCI", "GPS_RMC", "SSBL_FIX", "VIS")
    )
    return {
        "vehicle_hours": (t1 - t0) / 3600,
        "log_mb": raw.stat().st_size / 2**20,
        "lines": lines,
        "write_s": written,
        "import_s": seconds,
        "import_peak_rss_mb": rss,
        "target_s": TARGET_ACFR_S,
        "end_error_m": {"original": original, "imported": imported},
        "end_error_difference_mm": {k: 1e3 * abs(original[k] - imported[k]) for k in original},
    }, dive


def _with_camera(d):
    """The dive with a 1 Hz stereo camera's trigger log (its image names; no files)."""
    t0, t1 = d.time_span_s()
    t = np.arange(np.ceil(t0), t1, 1.0)
    names = [f"{k:06d}.jpg" for k in range(len(t))]
    left = np.array([f"left/{n}" for n in names])
    right = np.array([f"right/{n}" for n in names])
    return replace(d, images=ImageIndex(t, left, right))


def bench_bag(work: Path, dive_path: Path, gigabytes: float, version: int) -> dict:
    d = _with_camera(read_dive(dive_path))
    payload = 256 * 1024
    pairs = math.ceil(gigabytes * 2**30 / (2 * payload))
    if d.images is None or len(d.images) < pairs:
        raise RuntimeError(
            f"the dive has {0 if d.images is None else len(d.images)} image times; {pairs} are needed"
        )
    image = np.random.default_rng(0).integers(0, 256, payload, dtype=np.uint8).tobytes()
    results = {}
    settings = work / "ros.yaml"
    settings.write_text("heading_reference: magnetic\n")
    for label, n in (("baseline", 4), ("full", pairs)):
        bag = work / f"bag{version}_{label}" / ("dive.bag" if version == 1 else "dive_bag")
        if bag.parent.exists():
            shutil.rmtree(bag.parent)
        bag.parent.mkdir(parents=True)
        start = time.perf_counter()
        write_bag(d, bag, version=version, images=n, image_bytes=image)
        written = time.perf_counter() - start
        size = sum(p.stat().st_size for p in bag.parent.rglob("*") if p.is_file())
        out = work / f"bag{version}_{label}_dive"
        seconds, rss, summary = _timed_import(
            ["rosbag", str(bag), "--out", str(out), "--config", str(settings), "--overwrite"]
        )
        results[label] = {
            "bag_mb": size / 2**20,
            "images": 2 * n,
            "write_s": written,
            "import_s": seconds,
            "peak_rss_mb": rss,
            "messages": sum(v for k, v in summary["read"].items() if k.endswith("messages")),
        }
        shutil.rmtree(out, ignore_errors=True)
        shutil.rmtree(bag.parent, ignore_errors=True)
    results["target_rss_mb"] = TARGET_RSS_MB
    return results


def bench_magnetometer(seeds: int = 5) -> dict:
    from auvnav.compass.field import decimal_year2posix, earth_field
    from auvnav.compass.magnetometer import calibrate_magnetometer, distort_field
    from auvnav.errors import InsufficientDataError
    from auvnav.frames import euler2rot

    field = earth_field(math.radians(-14.05), math.radians(121.78), decimal_year2posix(2009.786))
    soft = np.array([[0.05, 0.02, -0.01], [0.02, -0.03, 0.015], [-0.01, 0.015, 0.04]])
    hard = np.array([0.2, -0.1, 0.15]) * field.total_T
    out: dict = {}
    for tilt in (10.0, 40.0):
        rows: dict[str, list] = {"general": [], "ellipsoid": [], "levelled": []}
        refused: list[str] = []
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            n = 1500
            heading = np.linspace(0.0, 6.0 * np.pi, n) + rng.uniform(0, 2 * np.pi)
            pitch = np.radians(tilt * np.sin(np.linspace(0.0, 23.0, n) + rng.uniform(0, 6)))
            roll = np.radians(tilt * np.sin(np.linspace(0.7, 31.0, n) + rng.uniform(0, 6)))
            b = np.einsum("nji,j->ni", euler2rot(heading + field.declination_rad, pitch, roll), field.b_ned_T)
            m = distort_field(b, soft, hard) + rng.normal(0.0, 1e-3 * field.total_T, b.shape)
            p_meas = pitch + rng.normal(0, math.radians(0.05), n)
            r_meas = roll + rng.normal(0, math.radians(0.05), n)
            for method, args in (
                ("general", dict(pitch_rad=0.0, roll_rad=0.0)),
                ("ellipsoid", dict(pitch_rad=p_meas, roll_rad=r_meas, inclination_rad=field.inclination_rad)),
                ("levelled", dict(pitch_rad=p_meas, roll_rad=r_meas, inclination_rad=field.inclination_rad)),
            ):
                try:
                    cal = calibrate_magnetometer(m, method=method, **args)
                except InsufficientDataError as err:
                    refused.append(f"{method}: {err}")
                    continue
                rows[method].append(
                    (
                        100 * cal.field_spread_after,
                        100 * np.max(np.abs(cal.h_hard_body - hard)) / field.total_T,
                    )
                )
        out[f"tilt_{tilt:g}_deg"] = {
            method: None
            if not r
            else {
                "calibrated": len(r),
                "field_spread_after_pct_max": max(x[0] for x in r),
                "hard_iron_error_pct_max": max(x[1] for x in r),
            }
            for method, r in rows.items()
        }
        out[f"tilt_{tilt:g}_deg"]["refused"] = sorted(set(refused))[:2]
        out[f"tilt_{tilt:g}_deg"]["refusals"] = len(refused)
    return out


def bench_igrf() -> float:
    import pymap3d

    from auvnav.compass.field import decimal_year2posix, earth_field

    rows = [  # tests/compass/test_field.py IGRF14_BGS (BGS pyIGRF, tests/tests_igrf14.py)
        (1900, 175, -150, 6300, (-5072.93, 10620.34, -67233.55)),
        (1915, 155, -120, 6350, (14692.62, 12387.97, -59640.81)),
        (1930, 135, -90, 6400, (23925.47, 10358.94, -30640.98)),
        (1945, 115, -60, 6450, (23642.86, -200.29, -7607.92)),
        (1960, 95, -30, 6500, (23647.00, -9302.27, -3610.73)),
        (1975, 75, 0, 6550, (30050.59, -3367.82, 6332.69)),
        (1990, 55, 30, 6600, (25224.81, 1058.25, 30965.61)),
        (2005, 35, 60, 6650, (14718.37, 2842.99, 46050.88)),
        (2020, 15, 90, 6700, (3734.07, 1294.17, 50833.13)),
        (2025, 90, 45, 6900, (25587.26, -826.43, -7422.32)),
    ]

    def basis(lat: float, lon: float) -> np.ndarray:
        sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])

    worst = 0.0
    for year, colat, lon, r_km, xyz in rows:
        lat_c, lon_r = math.radians(90 - colat), math.radians(lon)
        ecef = (
            1e3
            * r_km
            * np.array(
                [math.cos(lat_c) * math.cos(lon_r), math.cos(lat_c) * math.sin(lon_r), math.sin(lat_c)]
            )
        )
        lat, lon_g, h = pymap3d.ecef2geodetic(*ecef, deg=False)
        f = earth_field(lat, lon_g, decimal_year2posix(year), height_m=h, model="igrf")
        gc = basis(lat_c, lon_r) @ (basis(lat, lon_g).T @ f.b_ned_T) * 1e9
        d = math.degrees(math.atan2(gc[1], gc[0]) - math.atan2(xyz[1], xyz[0]))
        worst = max(worst, abs((d + 180) % 360 - 180))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--work", type=Path, default=None, help="keep the dives and logs here")
    parser.add_argument("--hours", type=float, default=6.0)
    parser.add_argument("--bag-gb", type=float, default=1.0)
    parser.add_argument("--skip-bag", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    work = args.work or Path(tempfile.mkdtemp(prefix="auvnav-bench-import-"))
    work.mkdir(parents=True, exist_ok=True)
    results: dict = {
        "igrf_max_declination_difference_deg": bench_igrf(),
        "magnetometer": bench_magnetometer(),
    }
    print(json.dumps(results, indent=2))
    acfr, dive = bench_acfr(work, args.hours)
    results["acfr"] = acfr
    print(json.dumps({"acfr": acfr}, indent=2))
    if not args.skip_bag:
        for version in (1, 2):
            results[f"rosbag{version}"] = bench_bag(work, dive, args.bag_gb, version)
            print(json.dumps({f"rosbag{version}": results[f"rosbag{version}"]}, indent=2))
    (work / "bench_import.json").write_text(json.dumps(results, indent=2))
    print(f"results in {work / 'bench_import.json'}")


if __name__ == "__main__":
    main()
