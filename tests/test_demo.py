"""``auvnav demo --quick``: the README's main command runs every stage end to end, and its figures
hold the paper's ordering (SLAM more consistent than the filter, the filter than dead reckoning; the
corrected survey far closer than the uncorrected one)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from auvnav.cli import main

pytestmark = pytest.mark.demo


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("demo") / "campaign"
    assert main(["demo", "--quick", "--out", str(out), "--json", "-q"]) == 0
    return out, json.loads((out / "summary.json").read_text(encoding="utf-8"))


def test_quick_demo_runs_every_stage_and_beats_dead_reckoning(demo) -> None:
    out, summary = demo
    navcheck = summary["dives"]["navcheck"]["evaluation"]
    dr, fil, slam = (navcheck[k]["ate_aligned_rmse_m"] for k in ("dr", "filter", "slam"))
    assert slam < fil < dr
    assert slam < 0.1  # the check dive's visual SLAM is consistent to decimetres or better
    loops = navcheck["loops"]
    assert summary["vision"]["nonconsecutive_accepted"] > 0
    assert loops["recall"] > 0.5 and loops["precision"] > 0.9
    assert (out / "navcheck" / "products" / "vision" / "loops.csv").is_file()
    head = summary["headline"]
    corrected = head["survey-corrected"]["onboard_end_error_m"]
    assert corrected < 0.5 * head["survey-uncorrected"]["onboard_end_error_m"]
    assert summary["compass"]["evaluation"]["shape_rmse_deg"] < 0.5


def test_demo_refuses_to_overwrite_without_the_flag(demo, capsys) -> None:
    out, _ = demo
    assert main(["demo", "--quick", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--overwrite" in err
