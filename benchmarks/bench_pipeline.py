"""``auvnav process`` killed and resumed: SIGKILL at random instants, then a rerun, against one run
that was not interrupted (issue 14 acceptance).

For each kill: a fresh copy of the simulated dive is processed and killed (SIGKILL, which nothing can
catch) at a random instant of the uninterrupted run's duration, then processed again to the end.
Checked after each rerun: every product is byte-identical to the uninterrupted run's (the CSV, TUM,
g2o and YAML products; the JSON summaries carry timings), no stage that had finished before the kill
ran again (the rerun says "up to date"), no temporary file or folder is left under ``products/``, and no
process of the killed run is left (its whole process tree, workers and forkserver included, was
recorded just before the kill). Also measured: the rerun of a dive with nothing changed.

Run: ``.venv/bin/python benchmarks/bench_pipeline.py [--work DIR] [--kills 10] [--seconds 1500]``
(``--seconds``: the check dive cut at this much vehicle time; 0 for the whole dive).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from treeusage import descendants

AUVNAV = str(Path(sys.executable).with_name("auvnav"))
PRODUCT_SUFFIXES = (".csv", ".tum", ".g2o", ".yaml")


def products(dive: Path) -> dict[str, bytes]:
    out = {}
    for path in sorted((dive / "products").rglob("*")):
        rel = path.relative_to(dive / "products")
        if path.is_file() and rel.parts[0] != "cache" and path.suffix in PRODUCT_SUFFIXES:
            out[str(rel)] = path.read_bytes()
    return out


def running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def process(dive: Path, *extra: str) -> tuple[float, dict]:
    started = time.perf_counter()
    out = subprocess.run(
        [AUVNAV, "process", str(dive), "--json", "-q", *extra], capture_output=True, text=True
    )
    if out.returncode != 0:
        raise SystemExit(f"auvnav process failed: {out.stderr}")
    return time.perf_counter() - started, json.loads(out.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/auvnav-bench-pipeline"))
    parser.add_argument("--kills", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=1500.0)
    parser.add_argument("--seed", type=int, default=12345)
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"cores {os.cpu_count()}, load average {os.getloadavg()}", flush=True)
    simulated = args.work / "simulated"
    if not (simulated / "images" / "index.csv").is_file():
        cut = ["--duration-s", str(args.seconds)] if args.seconds else []
        command = [
            AUVNAV,
            "simulate",
            "navcheck",
            "--out",
            str(simulated),
            "--seed",
            "0",
            "--image-scale",
            "0.5",
        ]
        subprocess.run([*command, "--overwrite", "-q", "--json", *cut], check=True, stdout=subprocess.DEVNULL)

    # Every copy is named as the simulated dive: products carry the dive's folder name.
    reference = args.work / "reference" / simulated.name
    shutil.rmtree(reference, ignore_errors=True)
    shutil.copytree(simulated, reference)
    full_s, first = process(reference)
    expected = products(reference)
    rerun_s, again = process(reference)
    statuses = {s["stage"]: s["status"] for s in again["stages"]}
    print(
        f"uninterrupted run {full_s:.1f} s; rerun with nothing changed {rerun_s:.2f} s: {statuses}",
        flush=True,
    )

    rng = random.Random(args.seed)
    rows = []
    for k in range(args.kills):
        dive = args.work / f"killed-{k}" / simulated.name
        shutil.rmtree(dive, ignore_errors=True)
        shutil.copytree(simulated, dive)
        at = rng.uniform(0.02, 0.98) * full_s
        proc = subprocess.Popen([AUVNAV, "process", str(dive), "-q"], stderr=subprocess.DEVNULL)
        deadline = time.perf_counter() + at
        while time.perf_counter() < deadline and proc.poll() is None:
            time.sleep(0.05)
        done_before = {
            p.parent.name
            for p in (dive / "products").glob("*/stage.json")
            if json.loads(p.read_text()).get("status") in ("ran", "skipped")
        }
        pids = descendants(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        time.sleep(2.0)  # workers notice their caller has gone at once; give the kernel a moment
        left_behind = [p for p in pids if p != proc.pid and running(p)]
        _, result = process(dive)
        rerun = {s["stage"]: s["status"] for s in result["stages"]}
        redone = sorted(name for name in done_before if rerun.get(name) == "ran")
        temporary = [str(p.relative_to(dive)) for p in (dive / "products").rglob(".*") if p.name != ".lock"]
        got = products(dive)
        differ = sorted(name for name in set(expected) | set(got) if expected.get(name) != got.get(name))
        row = {
            "kill": k,
            "at_s": round(at, 1),
            "finished_before": sorted(done_before),
            "rerun": rerun,
            "finished_stages_redone": redone,
            "temporary_left": temporary,
            "processes_left": left_behind,
            "products_differing": differ,
        }
        rows.append(row)
        ok = not (redone or temporary or left_behind or differ)
        print(
            f"kill {k} at {at:6.1f} s after {sorted(done_before)}: {'ok' if ok else 'FAILED ' + json.dumps(row)}"
        )
        shutil.rmtree(dive, ignore_errors=True)
    failures = [
        r
        for r in rows
        if r["finished_stages_redone"]
        or r["temporary_left"]
        or r["processes_left"]
        or r["products_differing"]
    ]
    summary = {
        "uninterrupted_s": full_s,
        "rerun_unchanged_s": rerun_s,
        "kills": len(rows),
        "failures": len(failures),
        "products_compared": len(expected),
        "rows": rows,
        "first_run": {s["stage"]: s["status"] for s in first["stages"]},
    }
    (args.work / "results.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    print(f"{len(rows)} kills, {len(failures)} failures; {len(expected)} product files compared each time")


if __name__ == "__main__":
    main()
