"""``auvnav process`` end to end on a small simulated check dive with images: every stage the data
allows, the same products as the stages' own commands, keys that skip what is up to date, settings
that rerun what follows, a dry run that writes nothing, and runs that are killed and resumed."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from auvnav.cli import main
from auvnav.pipeline import STAGES, process

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("pipeline")]  # one worker builds the dives

# A check dive small enough for a test: 2 arms of 6 m and a 2 m grid, quarter-size images (174 pairs).
SIMULATE = ["simulate", "navcheck", "--seed", "2", "--headings", "2", "--leg-m", "6", "--grid-m", "2"]
SIMULATE += ["--image-scale", "0.25", "--workers", "2", "-q", "--json"]


def _files(dive: Path) -> dict[str, bytes]:
    """Every product file's content by its path (caches, records and timing summaries aside)."""
    out = {}
    for path in sorted((dive / "products").rglob("*")):
        rel = path.relative_to(dive / "products")
        if path.is_file() and rel.parts[0] != "cache" and path.suffix in (".csv", ".tum", ".g2o", ".yaml"):
            out[str(rel)] = path.read_bytes()
    return out


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    dive = tmp_path_factory.mktemp("pipeline") / "navcheck"
    assert main([*SIMULATE, "--out", str(dive)]) == 0
    return dive


@pytest.fixture(scope="module")
def processed(simulated: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    dive = tmp_path_factory.mktemp("processed") / "navcheck"
    shutil.copytree(simulated, dive)
    result = process(dive, workers=2)
    return dive, {o.stage: o for o in result.outcomes}


def test_every_stage_the_data_allows_runs(processed) -> None:
    dive, outcomes = processed
    assert [s.name for s in STAGES] == list(outcomes)
    ran = {name for name, o in outcomes.items() if o.status == "ran"}
    assert ran == {"nav", "vision", "slam", "depth", "coverage", "recon", "report"}
    # Two arms of a star: the compass rose is not covered, so no correction is made, and it says why.
    assert outcomes["compass"].status == "skipped" and "compass rose" in outcomes["compass"].reason
    for name in ran:
        record = json.loads((dive / "products" / name / "stage.json").read_text(encoding="utf-8"))
        assert record["status"] == "ran" and len(record["key"]) == 64
    assert json.loads((dive / "products" / "compass" / "stage.json").read_text())["status"] == "skipped"
    assert (dive / "products" / "report" / "figures" / "fig6_depth.png").is_file()


def test_process_makes_the_products_the_commands_make(simulated: Path, processed, tmp_path: Path) -> None:
    dive, _ = processed
    separate = tmp_path / "navcheck"
    shutil.copytree(simulated, separate)
    commands = (["navigate"], ["loops", "--workers", "2"], ["slam"], ["depth"], ["coverage"], ["recon"])
    for command in commands:
        assert main([command[0], str(separate), *command[1:], "-q", "--json"]) == 0
    ours, theirs = _files(dive), _files(separate)
    assert set(ours) == set(theirs) and len(ours) > 10
    assert [name for name in ours if ours[name] != theirs[name]] == []


def test_a_rerun_skips_what_is_up_to_date(processed) -> None:
    dive, _ = processed
    before = _files(dive)
    result = process(dive)
    assert {o.stage: o.status for o in result.outcomes} == {
        "nav": "up to date",
        "vision": "up to date",
        "slam": "up to date",
        "compass": "skipped",
        "depth": "up to date",
        "coverage": "up to date",
        "recon": "up to date",
        "report": "up to date",
    }
    assert _files(dive) == before


def test_a_slam_setting_reruns_slam_and_what_follows_not_the_loops(processed, capsys) -> None:
    dive, _ = processed
    assert main(["process", str(dive), "--set", "slam.robust=huber", "--dry-run"]) == 0
    plan = capsys.readouterr().err
    assert "slam: would run (settings changed)" in plan and "vision: up to date" in plan
    assert main(["process", str(dive), "--set", "slam.robust=huber", "--json", "-q"]) == 0
    status = {s["stage"]: s["status"] for s in json.loads(capsys.readouterr().out)["stages"]}
    assert status["vision"] == "up to date" and status["slam"] == "ran" and status["report"] == "ran"
    summary = json.loads((dive / "products" / "slam" / "summary.json").read_text(encoding="utf-8"))
    assert summary["robust"] == "huber"
    assert main(["process", str(dive), "-q"]) == 0  # back to the defaults for the tests after this one


def test_only_from_force_and_bad_selections(processed, capsys) -> None:
    dive, _ = processed
    assert main(["process", str(dive), "--only", "loops", "--force", "--json", "-q"]) == 0
    status = {s["stage"]: s["status"] for s in json.loads(capsys.readouterr().out)["stages"]}
    assert status["vision"] == "ran" and status["nav"] == status["slam"] == "not selected"
    assert main(["process", str(dive), "--from", "depth", "--json", "-q"]) == 0
    status = {s["stage"]: s["status"] for s in json.loads(capsys.readouterr().out)["stages"]}
    assert status["nav"] == "not selected" and status["depth"] == "up to date"
    assert main(["process", str(dive), "--only", "mosaic"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no stage 'mosaic'" in err[0]


def test_a_dive_without_images_is_navigated_and_the_rest_skipped_with_reasons(tmp_path: Path, capsys) -> None:
    dive = tmp_path / "transit"
    assert (
        main(["simulate", "transit", "--out", str(dive), "--legs", "1", "--leg-m", "100", "--no-images"]) == 0
    )
    capsys.readouterr()
    assert main(["process", str(dive), "--json", "-q"]) == 0
    stages = {s["stage"]: s for s in json.loads(capsys.readouterr().out)["stages"]}
    assert stages["nav"]["status"] == "ran"
    assert "no images" in stages["vision"]["reason"] and "images/index.csv" in stages["slam"]["reason"]
    assert stages["compass"]["status"] == stages["depth"]["status"] == "skipped"


def test_bad_input_leaves_a_new_dive_without_a_products_folder(tmp_path: Path, capsys) -> None:
    """The lock and the file hashes are the run's bookkeeping: a run that fails before any stage
    writes takes them away again, and a run that succeeds keeps them."""
    dive = tmp_path / "transit"
    assert (
        main(["simulate", "transit", "--out", str(dive), "--legs", "1", "--leg-m", "100", "--no-images"]) == 0
    )
    dvl = dive / "nav" / "dvl.csv"
    good = dvl.read_text(encoding="utf-8")
    rows = good.splitlines()
    t, _, rest = rows[5].split(",", 2)
    dvl.write_text("\n".join([*rows[:5], f"{t},abc,{rest}", *rows[6:]]) + "\n", encoding="utf-8")
    capsys.readouterr()
    for command in (["process"], ["navigate"]):
        assert main([*command, str(dive), "-q"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert "dvl.csv: row 5: column vx_mps: not a number" in err[-1]
        assert not (dive / "products").exists(), command
    dvl.write_text(good, encoding="utf-8")
    assert main(["navigate", str(dive), "-q"]) == 0
    assert (dive / "products" / "cache" / "hashes.json").is_file()


# A caller that processes a dive and is killed part way; run as a separate process.
RUN = [sys.executable, "-c", "import sys; from auvnav.cli import main; sys.exit(main(sys.argv[1:]))"]


def _wait_for_worker_start(dive: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    features = dive / "products" / "cache" / "vision" / "features"
    while time.monotonic() < deadline and proc.poll() is None:
        if features.is_dir() and len(list(features.glob("*.feat"))) >= 10:
            return
        time.sleep(0.05)
    raise AssertionError("the loop stage did not start")


@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_a_killed_run_resumes_to_the_same_products(simulated: Path, processed, tmp_path: Path, how) -> None:
    """Killed in the middle of the loop stage: SIGTERM cleans up at once; SIGKILL leaves what the next
    run cleans up. Either way the rerun redoes no finished stage and ends with the same products."""
    reference, _ = processed
    dive = tmp_path / "navcheck"
    shutil.copytree(simulated, dive)
    proc = subprocess.Popen([*RUN, "process", str(dive), "--workers", "2", "-q"], env=os.environ.copy())
    _wait_for_worker_start(dive, proc)
    proc.send_signal(how)
    assert proc.wait(timeout=60) == (128 + how if how == signal.SIGTERM else -how)
    if how == signal.SIGTERM:  # nothing half-written is left
        assert not list((dive / "products").glob(".vision.*"))
        assert not list((dive / "products").rglob(".*.tmp"))
    assert not (dive / "products" / "vision").exists()
    assert (dive / "products" / "nav" / "stage.json").is_file()
    result = process(dive, workers=2)
    status = {o.stage: o.status for o in result.outcomes}
    assert status["nav"] == "up to date" and status["vision"] == "ran"
    assert not [p for p in (dive / "products").rglob(".*") if p.name != ".lock"]
    theirs = _files(reference)
    ours = _files(dive)
    assert [name for name in theirs if ours.get(name) != theirs[name]] == []


def test_two_runs_on_one_dive_do_not_mix(processed, capsys) -> None:
    from auvnav.pipeline import dive_lock

    dive, _ = processed
    with dive_lock(dive):
        assert main(["process", str(dive)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another auvnav is processing this dive" in err[0]
