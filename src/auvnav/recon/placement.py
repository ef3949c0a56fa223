"""Where each depth map goes: the pose of a pair's rectified left camera, and the tide at its time.

A pair's depth map is placed by the trajectory's body pose at the pair's time (interpolated), the stereo
rig's mount and the rectifying rotation: ``T_ned_rect = T_ned_body T_body_left T_left_rect`` with
``T_left_rect = (R1^T, 0)`` (:class:`~auvnav.vision.camera.Rectification`). Depth is depth below the
tide datum (DESIGN section 4) when a tide is known: a trajectory made from pressure depth (the
navigation's) is lowered by the tide ``eta(t)`` here; a SLAM trajectory solved with the tide already is
below the datum. The Fig. 11 check compares revisits placed with pressure depth, without and with the
tide (:func:`place_pairs`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray, se3
from auvnav.recon.dense import DenseGeometry
from auvnav.trajectory import Trajectory
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import T_body_cam


@dataclass(frozen=True)
class Placement:
    """Placed rectified left cameras of some pairs.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
    T_ned_rect : ndarray, shape (n, 4, 4)
        Pose of each pair's rectified left camera, metres, local NED (the products' placement).
    eta_m : ndarray, shape (n,)
        The tide at each pair (metres, up; zeros without a tide).
    p_body_ned_m : ndarray, shape (n, 3)
        The body's placed position.
    relief_before_m, relief_after_m : ndarray, shape (n,)
        What to add to an elevation as placed to have it from the pressure depth without, and with,
        the tide correction (the Fig. 11 check: :func:`place_pairs`).
    """

    t_s: FloatArray
    T_ned_rect: FloatArray
    eta_m: FloatArray
    p_body_ned_m: FloatArray
    relief_before_m: FloatArray
    relief_after_m: FloatArray

    def select(self, keep: NDArray[np.bool_]) -> Placement:
        """The placement of some pairs."""
        return Placement(
            self.t_s[keep],
            self.T_ned_rect[keep],
            self.eta_m[keep],
            self.p_body_ned_m[keep],
            self.relief_before_m[keep],
            self.relief_after_m[keep],
        )


def place_pairs(
    trajectory: Trajectory,
    t_s: FloatArray,
    rig: StereoRig,
    geom: DenseGeometry,
    *,
    eta_m: FloatArray | None = None,
    apply_tide: bool = True,
    tide_in_trajectory: bool = False,
    pressure_down_m: FloatArray | None = None,
) -> Placement:
    """Place pairs at times ``t_s`` (inside the trajectory) with the trajectory's poses.

    Parameters
    ----------
    trajectory : Trajectory
    t_s : ndarray, shape (n,)
    rig : StereoRig
    geom : DenseGeometry
        Gives the rectifying rotation ``R1``.
    eta_m : ndarray, shape (n,), optional
        The tide at each time, metres, up.
    apply_tide : bool
        Lower the trajectory by the tide (a trajectory whose depth is pressure depth). False keeps its
        depth as it is: a SLAM trajectory solved with the tide, or one solved without it whose loop
        closures already hold its revisits together (lowering it by the tide would then put steps
        between them; measured in ``benchmarks/bench_recon.py``).
    tide_in_trajectory : bool
        The trajectory's depth is already below the datum.
    pressure_down_m : ndarray, shape (n,), optional
        The pressure depth of the body at each time (the navigation's, tide not removed): the vertical
        of the Fig. 11 check, as a reconstruction placed with pressure depth would have it. Default:
        the trajectory's depth (plus the tide when it is already below the datum).
    """
    poses = trajectory.interpolate(np.asarray(t_s, dtype=float))
    tide = eta_m is not None
    eta = np.zeros(len(poses.t_s)) if eta_m is None else np.asarray(eta_m, dtype=float)
    down = poses.p_ned_m[:, 2]
    p = poses.p_ned_m.copy()
    if tide and apply_tide and not tide_in_trajectory:
        p[:, 2] -= eta
    if pressure_down_m is None:
        pressure = down + eta if tide_in_trajectory else down
    else:
        pressure = np.asarray(pressure_down_m, dtype=float)
    before = p[:, 2] - pressure  # elevation is minus depth: add (placed - pressure) depth
    T_ned_body = se3(poses.R_ned_body, p)
    T_left_rect = se3(np.asarray(geom.R1, dtype=float).T, np.zeros(3))
    T = T_ned_body @ T_body_cam(rig) @ T_left_rect
    return Placement(poses.t_s, T, eta, p, before, before + eta)
