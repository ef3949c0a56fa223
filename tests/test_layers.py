"""The layers of DESIGN section 3 are checked (``make lint`` runs ``lint-imports``): a model module that
imports a stage, or processing that imports the simulator, breaks the build."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(tree: Path) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` on a copy of the package under ``tree/src`` with the project's contracts."""
    return subprocess.run(
        [str(LINT), "--config", str(tree / "pyproject.toml"), "--no-cache"],
        cwd=tree,
        env={"PYTHONPATH": str(tree / "src"), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    if not LINT.exists():
        pytest.skip("lint-imports is not installed (pip install import-linter)")
    shutil.copytree(
        ROOT / "src" / "auvnav", tmp_path / "src" / "auvnav", ignore=shutil.ignore_patterns("__pycache__")
    )
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    return tmp_path


@pytest.mark.parametrize(
    ("module", "bad_import", "contract"),
    [
        ("nav/inputs.py", "import auvnav.vision.stage", "Models never import stages"),
        (
            "depth/stage.py",
            "import auvnav.slam.stage",
            "Stages import models of other domains, never each other",
        ),
        ("slam/graph.py", "import auvnav.sim.camera", "No processing module imports the simulator"),
        ("frames.py", "import auvnav.dive", "Layers of DESIGN section 3"),
        ("vision/features.py", "import matplotlib", "Plotting lives in report/"),
    ],
)
def test_a_bad_import_breaks_a_contract(tree: Path, module: str, bad_import: str, contract: str) -> None:
    path = tree / "src" / "auvnav" / module
    path.write_text(
        path.read_text(encoding="utf-8") + f"\n{bad_import}  # deliberately wrong\n", encoding="utf-8"
    )
    result = _lint(tree)
    assert result.returncode == 1, result.stdout
    broken = [line for line in result.stdout.splitlines() if line.endswith("BROKEN")]
    assert len(broken) >= 1 and any(line.startswith(contract) for line in broken), result.stdout
