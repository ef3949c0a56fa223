"""The reference headings a compass correction is fitted against: which file holds them."""

from __future__ import annotations

from pathlib import Path

from auvnav.products import SLAM_TRAJECTORY

#: Reference names and their files in a dive folder; anything else names a trajectory file.
REFERENCE_FILES: dict[str, Path] = {
    "truth": Path("truth") / "trajectory.csv",
    "slam": Path(SLAM_TRAJECTORY.rel),
}


def reference_file(dive_path: Path, reference: str) -> Path:
    """Where a dive's reference trajectory is: ``truth`` and ``slam`` in the dive folder, a file name in
    the dive folder if it is there, else as given (it need not exist)."""
    if reference in REFERENCE_FILES:
        return Path(dive_path) / REFERENCE_FILES[reference]
    inside = Path(dive_path) / reference
    return inside if inside.is_file() else Path(reference)
