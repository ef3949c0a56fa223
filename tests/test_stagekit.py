"""Stage settings from files, ``--set`` and options: typed, bounded, strict, paths relative to a
settings file; the products registry and the atomic product set."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from auvnav import products as P
from auvnav.cli import main
from auvnav.compass.stage import CompassSettings
from auvnav.errors import AuvnavError, ConfigError
from auvnav.slam.stage import SlamSettings
from auvnav.stagekit import make_settings, settings_mapping


def test_values_are_coerced_to_the_field_types(tmp_path: Path) -> None:
    s = make_settings(
        SlamSettings,
        {"robust": "huber", "harmonics": "2", "estimate_compass": "yes", "tide": "tide.csv"},
        "here",
        base=tmp_path,
    )
    assert s.robust == "huber" and s.harmonics == 2 and s.estimate_compass is True
    assert s.tide == tmp_path / "tide.csv"  # relative to the settings file's folder
    assert settings_mapping(s)["tide"] == str(tmp_path / "tide.csv")
    c = make_settings(CompassSettings, {"transits": ["a", "b"]}, "here")
    assert c.transits == (Path("a"), Path("b"))


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"robustness": "huber"}, "unknown setting 'robustness'"),
        ({"robust": "tukey"}, "expected one of none, huber, cauchy"),
        ({"harmonics": -1}, "must be in [0, inf]"),
        ({"harmonics": 2.5}, "expected an integer"),
        ({"compass_sigma_deg": float("nan")}, "must be finite"),
        ({"estimate_compass": "maybe"}, "expected true or false"),
        ({"incremental": None}, "must be given"),
        ({"loops": 3}, "expected a file path"),
    ],
)
def test_bad_values_name_the_setting(values: dict, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        make_settings(SlamSettings, values, "settings.yaml: slam")
    assert message in str(err.value) and str(err.value).startswith("settings.yaml: slam")


def test_bad_settings_file_and_set_are_one_line_errors(tmp_path: Path, capsys) -> None:
    dive = tmp_path / "dive"
    dive.mkdir()
    settings = tmp_path / "settings.yaml"
    settings.write_text("slam:\n  robust: tukey\n")
    assert main(["process", str(dive), "--settings", str(settings), "--dry-run"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "settings.yaml: slam: robust: expected one of" in err[0]
    settings.write_text("mosaic: {}\n")
    assert main(["process", str(dive), "--settings", str(settings), "--dry-run"]) == 1
    assert "no stage 'mosaic'" in capsys.readouterr().err
    assert main(["process", str(dive), "--set", "slam.robust", "--dry-run"]) == 2  # usage
    assert "STAGE.KEY=VALUE" in capsys.readouterr().err


def test_a_product_set_appears_whole_or_not_at_all(tmp_path: Path) -> None:
    old = P.stage_dir(tmp_path, "nav")
    old.mkdir(parents=True)
    (old / "dr.csv").write_text("old\n")
    with pytest.raises(RuntimeError), P.ProductSet(tmp_path, "nav") as folder:
        (folder / "dr.csv").write_text("half\n")
        raise RuntimeError("the stage failed")
    assert (old / "dr.csv").read_text() == "old\n"
    assert [p.name for p in (tmp_path / "products").iterdir()] == ["nav"]
    product_set = P.ProductSet(tmp_path, "nav")
    with product_set as folder:
        (folder / "dr.csv").write_text("new\n")
        product_set.commit({"key": "k"})
    assert sorted(p.name for p in old.iterdir()) == ["dr.csv", "stage.json"]
    assert (old / "dr.csv").read_text() == "new\n" and P.read_record(tmp_path, "nav") == {"key": "k"}


def test_recover_completes_a_swap_killed_between_its_renames(tmp_path: Path) -> None:
    """Killed after the old set was moved aside: the new complete set is put in place; a new set
    without its stage.json (killed while writing) is removed."""
    root = tmp_path / "products"
    (root / ".nav.old-x").mkdir(parents=True)
    (root / ".nav.old-x" / "dr.csv").write_text("old\n")
    (root / ".nav.new-y").mkdir()
    (root / ".nav.new-y" / "dr.csv").write_text("new\n")
    (root / ".nav.new-y" / P.STAGE_FILE).write_text(json.dumps({"key": "k"}))
    (root / ".nav.new-z").mkdir()
    P.recover(tmp_path, "nav")
    assert sorted(p.name for p in root.iterdir()) == ["nav"]
    assert (root / "nav" / "dr.csv").read_text() == "new\n"


def test_a_products_path_that_is_a_file_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "products").mkdir()
    (tmp_path / "products" / "nav").write_text("not a folder")
    with (
        pytest.raises(AuvnavError, match="products/nav: exists and is not a folder"),
        P.ProductSet(tmp_path, "nav"),
    ):
        pass


def test_an_earlier_releases_name_is_read_with_a_warning(tmp_path: Path) -> None:
    old = tmp_path / "products" / "slam" / "compass_correction.yaml"
    old.parent.mkdir(parents=True)
    old.write_text("x")
    with pytest.warns(DeprecationWarning, match="products/slam/correction.yaml"):
        assert P.existing(tmp_path, P.SLAM_CORRECTION) == old
    assert P.existing(tmp_path, P.SLAM_TRAJECTORY) is None
