"""Figures (the only place that imports matplotlib). Each function draws one figure into a file.

Functions are small and independent: they take arrays or trajectories and a path, and return the path.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from auvnav.streams import atomic_write
from auvnav.trajectory import Trajectory


def plot_tracks(
    tracks: Sequence[tuple[str, Trajectory]],
    path: Path,
    *,
    title: str = "",
    dpi: int = 120,
) -> Path:
    """Plan view of trajectories (east right, north up), e.g. true against onboard tracks.

    Parameters
    ----------
    tracks : sequence of (label, Trajectory)
        Drawn in order, each in its own colour; positions in metres, local NED.
    path : Path
        PNG file to write.
    title : str
    dpi : int

    Returns
    -------
    Path
    """
    fig, ax = plt.subplots(figsize=(7, 7))
    for label, traj in tracks:
        ax.plot(traj.p_ned_m[:, 1], traj.p_ned_m[:, 0], lw=0.6, label=label)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    atomic_write(Path(path), lambda p: fig.savefig(p, dpi=dpi, format="png"))
    plt.close(fig)
    return Path(path)
