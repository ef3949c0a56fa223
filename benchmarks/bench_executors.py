"""The loop-closure stage through each executor: local processes, a Dask ``LocalCluster`` of 2 and of 1
worker processes (issue 14 acceptance).

Each run starts from an empty feature and verification cache on the same check dive (half scale, its
navigation done) and runs the loop stage alone; reported: wall time, stereo pairs per second, the
ratio to the local run, and whether ``loops.csv`` is byte-identical to the local run's.

Run: ``.venv/bin/python benchmarks/bench_executors.py [--work DIR] [--seconds 0]`` (``--seconds``:
the check dive cut at this much vehicle time; 0, the default, for the whole dive).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

AUVNAV = str(Path(sys.executable).with_name("auvnav"))
RUNS = {"local": [], "dask local:2": ["--scheduler", "local:2"], "dask local:1": ["--scheduler", "local:1"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/auvnav-bench-executors"))
    parser.add_argument("--seconds", type=float, default=0.0)
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"cores {os.cpu_count()}, load average {os.getloadavg()}", flush=True)
    dive = args.work / "navcheck"
    if not (dive / "images" / "index.csv").is_file():
        cut = ["--duration-s", str(args.seconds)] if args.seconds else []
        command = [AUVNAV, "simulate", "navcheck", "--out", str(dive), "--seed", "0", "--image-scale", "0.5"]
        subprocess.run([*command, "--overwrite", "-q", "--json", *cut], check=True, stdout=subprocess.DEVNULL)
    subprocess.run(
        [AUVNAV, "process", str(dive), "--only", "nav", "-q"], check=True, stdout=subprocess.DEVNULL
    )
    results: dict[str, dict] = {}
    loops: dict[str, bytes] = {}
    for name, options in RUNS.items():
        shutil.rmtree(dive / "products" / "cache" / "vision", ignore_errors=True)
        started = time.perf_counter()
        out = subprocess.run(
            [AUVNAV, "process", str(dive), "--only", "vision", "--force", "--json", "-q", *options],
            capture_output=True,
            text=True,
            check=True,
        )
        wall = time.perf_counter() - started
        summary = next(s for s in json.loads(out.stdout)["stages"] if s["stage"] == "vision")["summary"]
        loops[name] = (dive / "products" / "vision" / "loops.csv").read_bytes()
        results[name] = {
            "wall_s": wall,
            "stage_s": summary["elapsed_s"],
            "features_s": summary["features_s"],
            "pairs_per_s": summary["pairs_per_s"],
            "workers": summary["workers"],
            "loops_identical_to_local": loops[name] == loops["local"],
        }
        ratio = summary["pairs_per_s"] / results["local"]["pairs_per_s"]
        print(
            f"{name:13s} {summary['pairs_per_s']:6.2f} pairs/s ({summary['elapsed_s']:.0f} s, features "
            f"{summary['features_s']:.0f} s), {ratio:.3f} of local, loops.csv identical: "
            f"{results[name]['loops_identical_to_local']}",
            flush=True,
        )
    results["load_average_end"] = {"load": os.getloadavg()}
    (args.work / "results.json").write_text(json.dumps(results, indent=2), encoding="utf-8")


if __name__ == "__main__":
    main()
