"""An extended Kalman filter and Rauch-Tung-Striebel smoother fusing DVL, attitude, depth and fixes.

State, at filter epochs ``T_k`` (a regular grid of ``period_s`` plus the time of every fix):

========== ======================================================== ==============================
index      meaning                                                  model
========== ======================================================== ==============================
0, 1, 2    north, east, down of the reference point, metres, NED    driven by the DVL
3          heading error ``beta``, radians                          random walk from
                                                                    ``heading_bias_sigma_rad``,
                                                                    ``heading_bias_walk``
4          DVL scale error ``kappa``: true = (1 + kappa) x measured random constant,
                                                                    ``dvl_scale_sigma``
5 ...      compass deviation harmonics ``a1, b1, ..., aH, bH``,     random constants,
           radians (paper eq. 5 without its constant)               ``deviation_sigma_rad``
========== ======================================================== ==============================

The true heading is the navigated heading plus ``beta + sum_k a_k cos(k h) + b_k sin(k h)``, ``h``
the heading as the compass gave it: ``beta`` takes the deviation's constant term, the DVL's yaw
misalignment and whatever drifts; the harmonics take the part that changes with heading, which a
survey's alternating lines turn into the 'accordion' (paper Fig. 2) and which no slowly varying
``beta`` can follow.

Between epochs the DVL displacement ``D`` (the trapezoidal integral of the navigated
``R_ned_body v`` over the interval at the sensors' full rate, :mod:`auvnav.nav.inputs`), the change
of the DVL lever arm ``Dl`` and the harmonic-weighted displacements ``W_m = sum_i phi_m(h_i) d_i``
(``phi`` = cos k h, sin k h; ``d_i`` the DVL's horizontal steps) move the position:
``p_ne += Rz(beta) ((1 + kappa) D_ne + Dl_ne + J sum_m c_m W_m)``, ``J`` the quarter turn
``(n, e) -> (-e, n)``, ``down += D_d + Dl_d`` (the scale error is left out of the vertical: the
pressure depth rules there, and a bridged descent or the tide would leak into ``kappa``). ``beta`` enters exactly (the EKF linearises
``Rz(beta)`` about its estimate), the harmonics to first order (a degree or two: the neglected second
order is below 0.06% of the distance). Pitch and roll are the measured ones, smoothed
(:func:`auvnav.nav.inputs.smooth_tilt`).

Process noise: white DVL noise, ``(sigma_v dt)^2`` per sample and axis; across a bridged dropout of
length ``T_g`` an error correlated over the dropout, ``sigma_b^2 T_g dt`` per sample, so that the
variance added by the whole dropout is ``(sigma_b T_g)^2``, with ``sigma_b`` a floor plus a fraction
of the fastest horizontal velocity bridged (a vehicle hovering through a descent bridges little, one
cruising through a mid-line dropout more; vertically, of the fastest velocity in 3D, so the pressure
depth rules a bridged descent); vertically, also a tilt error mapping the interval's displacement
into depth, ``(sigma_tilt |D|)^2``. ``beta`` is a random walk rather than a
Gauss-Markov process: a constant error (one steady transit) stays one instead of being pulled back
to zero between fixes, which would bend a straight transit.

Measurements: the pressure depth at every epoch; GPS and USBL horizontal fixes (antenna lever arm
removed), each gated by its squared Mahalanobis distance against the chi-square quantile with 2
degrees of freedom at ``gate_probability``. When ``reset_after`` consecutive fixes of one sensor are
rejected the filter is judged lost (its model under-states the drift) rather than the fixes wrong:
the innovation's outer product is added to the position covariance and the fix is used. Every fix's
innovation and innovation covariance is logged (the paper's Fig. 9).

The filter starts at the first sample from :func:`auvnav.nav.deadreckon.start_position`: with a fix,
a diffuse prior (``diffuse_sigma_m``) at the first fix carried back, so the fixes alone place the
track; without one, at the dive's origin with ``origin_sigma_m``. The smoother (Rauch, Tung and
Striebel, "Maximum likelihood estimates of linear dynamic systems", AIAA J. 3(8), 1965) then carries
every fix back along the track, the part before the first fix included. Between epochs the smoothed
track follows the full-rate displacements under the smoothed state, with the smoother's correction
of each interval spread linearly in time.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from auvnav.errors import ConfigError
from auvnav.frames import FloatArray, wrap_angle
from auvnav.nav.deadreckon import Start
from auvnav.nav.inputs import NavInputs, interp_rows
from auvnav.trajectory import Trajectory
from auvnav.vehicle import Vehicle

log = logging.getLogger(__name__)

_N, _E, _D, _BETA, _KAPPA = range(5)
_HARMONICS0 = 5  # index of a1
#: The heading error's random walk adds the compass's sigma in quadrature over this time, s: the
#: error of a compass calibrated to a degree (paper sec. II-C) may wander that much over an hour.
HEADING_BIAS_WALK_S = 3600.0


@dataclass(frozen=True)
class FilterConfig:
    """Noise model and tuning of the filter (1-sigma, SI units).

    Parameters
    ----------
    dvl_velocity_sigma_mps : float
        White DVL velocity noise per sample.
    dvl_scale_sigma : float
        Prior of the DVL scale error.
    heading_bias_sigma_rad : float
        Prior sigma of the heading error ``beta``.
    heading_bias_walk : float
        Random walk of ``beta``, rad per square root of a second.
    deviation_sigma_rad : float
        Prior sigma of each deviation harmonic coefficient.
    tilt_sigma_rad : float
        Pitch and roll error, mapping displacement into depth.
    depth_sigma_m : float
        Pressure depth noise.
    deviation_harmonics : int
        Harmonics of the deviation estimated (0: none); eq. 5 with three is the paper's correction,
        two are enough for what a correction leaves and what the start and end of a dive can see.
    bridge_velocity_sigma_mps : float
        Floor of the error of a velocity bridged across a dropout.
    bridge_speed_fraction : float
        Part of the fastest bridged speed added to that floor (the speed may change by a tenth
        through a dropout: a modelling guess, not a datasheet figure).
    period_s : float
        Spacing of the filter epochs (the DVL's full rate still drives the displacement).
    gate_probability : float
        Chi-square gate of the fixes (2 degrees of freedom).
    reset_after : int
        Consecutive rejected fixes of one sensor after which the filter resets its position.
    diffuse_sigma_m : float
        Horizontal prior when fixes place the track.
    origin_sigma_m : float
        Horizontal prior at the dive's origin when there are no fixes.
    """

    dvl_velocity_sigma_mps: float
    dvl_scale_sigma: float
    heading_bias_sigma_rad: float
    heading_bias_walk: float
    deviation_sigma_rad: float
    tilt_sigma_rad: float
    depth_sigma_m: float
    deviation_harmonics: int = 2
    bridge_velocity_sigma_mps: float = 0.01
    bridge_speed_fraction: float = 0.1
    period_s: float = 1.0
    gate_probability: float = 0.999
    reset_after: int = 3
    diffuse_sigma_m: float = 1000.0
    origin_sigma_m: float = 3.0

    def __post_init__(self) -> None:
        for name in (
            "dvl_velocity_sigma_mps",
            "dvl_scale_sigma",
            "heading_bias_sigma_rad",
            "heading_bias_walk",
            "deviation_sigma_rad",
            "tilt_sigma_rad",
            "depth_sigma_m",
            "bridge_velocity_sigma_mps",
            "bridge_speed_fraction",
            "period_s",
            "diffuse_sigma_m",
            "origin_sigma_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"filter setting {name} must be a positive number; found {value!r}")
        if not 0.5 < self.gate_probability < 1.0:
            raise ConfigError(
                f"filter setting gate_probability must lie in (0.5, 1); found {self.gate_probability}"
            )
        if self.reset_after < 1:
            raise ConfigError(f"filter setting reset_after must be at least 1; found {self.reset_after}")
        if self.deviation_harmonics < 0:
            raise ConfigError(
                f"filter setting deviation_harmonics must be 0 or more; found {self.deviation_harmonics}"
            )

    @classmethod
    def for_vehicle(cls, vehicle: Vehicle, depth_sigma_m: float) -> FilterConfig:
        """The noise model of a vehicle's sensors (vehicle.yaml), other settings at their defaults.

        The heading error and each deviation harmonic start at the compass's sigma; the heading error
        wanders by as much again every :data:`HEADING_BIAS_WALK_S` seconds.

        Parameters
        ----------
        vehicle : Vehicle
        depth_sigma_m : float
            The pressure sensor's sigma as depth, metres (it depends on latitude through gravity).
        """
        return cls(
            dvl_velocity_sigma_mps=vehicle.dvl_velocity_sigma_mps,
            dvl_scale_sigma=vehicle.dvl_scale_sigma,
            heading_bias_sigma_rad=vehicle.heading_sigma_rad,
            heading_bias_walk=vehicle.heading_sigma_rad / math.sqrt(HEADING_BIAS_WALK_S),
            deviation_sigma_rad=vehicle.heading_sigma_rad,
            tilt_sigma_rad=vehicle.pitch_roll_sigma_rad,
            depth_sigma_m=depth_sigma_m,
        )

    @property
    def n_state(self) -> int:
        """Length of the state vector."""
        return _HARMONICS0 + 2 * self.deviation_harmonics

    @property
    def gate_mahalanobis(self) -> float:
        """The gate on the Mahalanobis distance: the chi-square quantile with 2 dof is ``-2 ln(1-p)``."""
        return math.sqrt(-2.0 * math.log1p(-self.gate_probability))


@dataclass(frozen=True)
class Innovations:
    """The position innovations of the forward filter, one row per fix (the paper's Fig. 9).

    Parameters
    ----------
    t_s : ndarray, shape (M,)
        POSIX seconds.
    sensor : ndarray of str, shape (M,)
        ``"gps"`` or ``"usbl"``.
    nu_ne_m : ndarray, shape (M, 2)
        Fix minus prediction, north and east, metres.
    S_ne_m2 : ndarray, shape (M, 2, 2)
        Innovation covariance, square metres.
    mahalanobis : ndarray, shape (M,)
        ``sqrt(nu^T S^-1 nu)``.
    accepted : ndarray of bool, shape (M,)
        Used by the filter (inside the gate, or a reset).
    reset : ndarray of bool, shape (M,)
        The filter reset its position on this fix.
    """

    t_s: FloatArray
    sensor: NDArray[np.str_]
    nu_ne_m: FloatArray
    S_ne_m2: FloatArray
    mahalanobis: FloatArray
    accepted: NDArray[np.bool_]
    reset: NDArray[np.bool_]

    def __post_init__(self) -> None:
        m = np.shape(self.t_s)
        shapes = {
            "sensor": m,
            "nu_ne_m": (*m, 2),
            "S_ne_m2": (*m, 2, 2),
            "mahalanobis": m,
            "accepted": m,
            "reset": m,
        }
        for name, want in shapes.items():
            if np.shape(getattr(self, name)) != want:
                raise ValueError(
                    f"Innovations.{name} must have shape {want}; found {np.shape(getattr(self, name))}"
                )

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def sigma_ne_m(self) -> FloatArray:
        """1-sigma of the innovation, north and east, shape (M, 2), metres."""
        return np.sqrt(np.diagonal(self.S_ne_m2, axis1=1, axis2=2))

    def inside(self, n_sigma: float = 2.0) -> NDArray[np.bool_]:
        """Which north and east innovations lie inside ``+-n_sigma`` sigma, shape (M, 2).

        Per component, as the paper's Fig. 9 draws them: for a consistent filter about 95% lie
        inside 2 sigma.
        """
        return np.abs(self.nu_ne_m) <= n_sigma * self.sigma_ne_m

    def to_frame(self) -> pd.DataFrame:
        """The file form (``innovations.csv``)."""
        sigma = self.sigma_ne_m
        return pd.DataFrame(
            {
                "t": self.t_s,
                "sensor": self.sensor,
                "innovation_north_m": self.nu_ne_m[:, 0],
                "innovation_east_m": self.nu_ne_m[:, 1],
                "sigma_north_m": sigma[:, 0],
                "sigma_east_m": sigma[:, 1],
                "cov_north_east_m2": self.S_ne_m2[:, 0, 1],
                "mahalanobis": self.mahalanobis,
                "accepted": self.accepted.astype(int),
                "reset": self.reset.astype(int),
            }
        )


@dataclass(frozen=True)
class FilterResult:
    """What :func:`run_filter` gives.

    Parameters
    ----------
    smoothed : Trajectory
        The smoothed track on the navigation time base, with 1-sigma position and heading.
    innovations : Innovations
    heading_error_rad : ndarray, shape (N,)
        Smoothed heading correction on the time base, ``beta + sum_k a_k cos(k h) + b_k sin(k h)``.
    dvl_scale_error, dvl_scale_sigma : float
        Smoothed DVL scale error ``kappa`` and its 1-sigma.
    deviation_rad, deviation_sigma_rad : ndarray, shape (2H,)
        Smoothed deviation harmonics ``[a1, b1, ..., aH, bH]`` and their 1-sigma, radians.
    """

    smoothed: Trajectory
    innovations: Innovations
    heading_error_rad: FloatArray
    dvl_scale_error: float
    dvl_scale_sigma: float
    deviation_rad: FloatArray
    deviation_sigma_rad: FloatArray


def _epochs(t_s: FloatArray, period_s: float, fix_times: FloatArray) -> FloatArray:
    grid = np.arange(t_s[0], t_s[-1], period_s)
    return np.unique(np.concatenate([grid, fix_times, t_s[-1:]]))


def process_variance(inputs: NavInputs, cfg: FilterConfig) -> tuple[FloatArray, FloatArray]:
    """Cumulative process variance per horizontal axis and vertically at each sample, m^2, shape (N,).

    Across a dropout the horizontal error scales with the fastest horizontal speed bridged, the
    vertical one with the fastest speed in 3D (a descent's bridged vertical rate is a guess too).
    """
    t = inputs.t_s
    dt = np.diff(t)
    q_h = (cfg.dvl_velocity_sigma_mps * dt) ** 2
    q_v = q_h.copy()
    bridged = inputs.bridged[1:] | inputs.bridged[:-1]
    drop = inputs.dropouts
    if drop.count and np.any(bridged):
        mid = 0.5 * (t[1:] + t[:-1])[bridged]
        run = np.clip(np.searchsorted(drop.start_s, mid, side="right") - 1, 0, drop.count - 1)
        v_ned = np.einsum("nij,nj->ni", inputs.R_ned_body, inputs.v_body_mps)
        for q, speed in ((q_h, np.hypot(v_ned[:, 0], v_ned[:, 1])), (q_v, np.linalg.norm(v_ned, axis=1))):
            fastest = np.zeros(drop.count)
            np.maximum.at(fastest, run, np.maximum(speed[1:], speed[:-1])[bridged])
            sigma = cfg.bridge_velocity_sigma_mps + cfg.bridge_speed_fraction * fastest[run]
            q[bridged] = sigma**2 * drop.duration_s[run] * dt[bridged]
    return np.concatenate([[0.0], np.cumsum(q_h)]), np.concatenate([[0.0], np.cumsum(q_v)])


def _harmonics(h_rad: FloatArray, n: int) -> FloatArray:
    """``[cos h, sin h, ..., cos n h, sin n h]`` of compass headings, shape (..., 2n)."""
    k = np.arange(1, n + 1)
    angles = np.asarray(h_rad)[..., None] * k
    return np.stack([np.cos(angles), np.sin(angles)], -1).reshape(*np.shape(h_rad), 2 * n)


def _weighted_displacement(inputs: NavInputs, C: FloatArray, n: int) -> FloatArray:
    """Cumulative harmonic-weighted horizontal DVL displacements ``W``, shape (N, 2n, 2), metres."""
    steps = np.diff(C[:, :2], axis=0)
    unit = np.exp(1j * inputs.compass_heading_rad)
    h_mid = np.angle(unit[1:] + unit[:-1])  # the compass heading halfway through each step
    weighted = _harmonics(h_mid, n)[:, :, None] * steps[:, None, :]
    return np.concatenate([np.zeros((1, 2 * n, 2)), np.cumsum(weighted, axis=0)])


def _move(
    beta: FloatArray,
    kappa: FloatArray,
    deviation: FloatArray,
    d_dvl: FloatArray,
    d_lever: FloatArray,
    d_weighted: FloatArray,
) -> FloatArray:
    """Displacements under the state; shapes (M,), (M,), (M, 2H), (M, 3), (M, 3), (M, 2H, 2)."""
    g = np.einsum("mh,mhj->mj", deviation, d_weighted)
    hn = (1.0 + kappa) * d_dvl[:, 0] + d_lever[:, 0] - g[:, 1]
    he = (1.0 + kappa) * d_dvl[:, 1] + d_lever[:, 1] + g[:, 0]
    c, s = np.cos(beta), np.sin(beta)
    return np.stack([c * hn - s * he, s * hn + c * he, d_dvl[:, 2] + d_lever[:, 2]], -1)


def run_filter(inputs: NavInputs, start: Start, cfg: FilterConfig) -> FilterResult:
    """Filter forward and smooth backward (see the module docstring).

    Parameters
    ----------
    inputs : NavInputs
    start : Start
        Where the track starts (:func:`auvnav.nav.deadreckon.start_position`).
    cfg : FilterConfig

    Returns
    -------
    FilterResult
    """
    t = inputs.t_s
    fix_times = np.concatenate([f.t_s for f in inputs.fixes]) if inputs.fixes else np.zeros(0)
    T = _epochs(t, cfg.period_s, fix_times)
    K, n_state, n_dev = len(T), cfg.n_state, 2 * cfg.deviation_harmonics

    # Quantities at the epochs and over each interval.
    C = inputs.dvl_displacement_ned_m()
    L = inputs.lever_arm_ned_m()
    W = _weighted_displacement(inputs, C, cfg.deviation_harmonics)
    CT, LT, WT = interp_rows(T, t, C), interp_rows(T, t, L), interp_rows(T, t, W)
    D_dvl, D_lever, D_weighted = np.diff(CT, axis=0), -np.diff(LT, axis=0), np.diff(WT, axis=0)
    Q_h, Q_v = process_variance(inputs, cfg)
    q_h = np.diff(np.interp(T, t, Q_h))
    q_d = np.diff(np.interp(T, t, Q_v)) + (cfg.tilt_sigma_rad * np.linalg.norm(D_dvl, axis=1)) ** 2
    q_beta = cfg.heading_bias_walk**2 * np.diff(T)
    depth_T = np.interp(T, t, inputs.depth_m)
    r_depth = cfg.depth_sigma_m**2

    # Fixes by epoch: (sensor, north, east, sigma), lever arm already removed.
    at_epoch: dict[int, list[tuple[str, float, float, float]]] = {}
    for f in inputs.fixes:
        lever = np.einsum("nij,j->ni", inputs.R_ned_body_at(f.t_s), f.lever_arm_body_m)
        p = f.p_ned_m - lever
        for k, pn, pe, s in zip(np.searchsorted(T, f.t_s), p[:, 0], p[:, 1], f.sigma_m, strict=True):
            at_epoch.setdefault(int(k), []).append((f.sensor, float(pn), float(pe), float(s)))

    sigma0 = cfg.origin_sigma_m if start.source == "origin" else cfg.diffuse_sigma_m
    x = np.zeros(n_state)
    x[[_N, _E, _D]] = start.p_ne_m[0], start.p_ne_m[1], depth_T[0]
    P = np.diag(
        [sigma0**2, sigma0**2, r_depth, cfg.heading_bias_sigma_rad**2, cfg.dvl_scale_sigma**2]
        + [cfg.deviation_sigma_rad**2] * n_dev
    )
    xp, xf = np.empty((K, n_state)), np.empty((K, n_state))
    Pp, Pf = np.empty((K, n_state, n_state)), np.empty((K, n_state, n_state))
    F_all = np.empty((max(K - 1, 0), n_state, n_state))
    log_rows: list[tuple[float, str, float, float, FloatArray, float, bool, bool]] = []
    rejected_run: dict[str, int] = {}
    gate = cfg.gate_mahalanobis
    eye = np.eye(n_state)
    dev = slice(_HARMONICS0, n_state)

    for k in range(K):
        if k > 0:
            j = k - 1
            beta, kappa = x[_BETA], x[_KAPPA]
            c, s = math.cos(beta), math.sin(beta)
            dn, de, dd = D_dvl[j]
            ln, le, ld = D_lever[j]
            Wn, We = D_weighted[j, :, 0], D_weighted[j, :, 1]
            g_n, g_e = float(x[dev] @ Wn), float(x[dev] @ We)
            hn, he = (1.0 + kappa) * dn + ln - g_e, (1.0 + kappa) * de + le + g_n
            F = eye.copy()
            F[_N, _BETA], F[_E, _BETA] = -s * hn - c * he, c * hn - s * he
            F[_N, _KAPPA], F[_E, _KAPPA] = c * dn - s * de, s * dn + c * de
            F[_N, dev], F[_E, dev] = -c * We - s * Wn, -s * We + c * Wn  # Rz(beta) J W
            x = x.copy()
            x[_N] += c * hn - s * he
            x[_E] += s * hn + c * he
            x[_D] += dd + ld
            P = F @ P @ F.T
            P[_N, _N] += q_h[j]
            P[_E, _E] += q_h[j]
            P[_D, _D] += q_d[j]
            P[_BETA, _BETA] += q_beta[j]
            F_all[j] = F
        xp[k], Pp[k] = x, P

        # Pressure depth.
        Pd = P[:, _D].copy()
        gain = Pd / (Pd[_D] + r_depth)
        x = x + gain * (depth_T[k] - x[_D])
        P = P - np.outer(gain, Pd)

        for sensor, pn, pe, sigma in at_epoch.get(k, ()):
            nu = np.array([pn - x[_N], pe - x[_E]])
            S = P[:2, :2] + sigma**2 * np.eye(2)
            d = math.sqrt(max(float(nu @ np.linalg.solve(S, nu)), 0.0))
            accept, reset = d <= gate, False
            if not accept:
                rejected_run[sensor] = rejected_run.get(sensor, 0) + 1
                if rejected_run[sensor] >= cfg.reset_after:
                    accept = reset = True
                    log.warning(
                        "filter: %d consecutive %s fixes rejected (innovation %.1f m, %.1f sigma) at t=%.1f; "
                        "position reset: the drift is larger than the noise model allows",
                        rejected_run[sensor],
                        sensor,
                        float(np.hypot(*nu)),
                        d,
                        T[k],
                    )
                    P[:2, :2] += np.outer(nu, nu)
                    Pp[k, :2, :2] += np.outer(nu, nu)
            log_rows.append((float(T[k]), sensor, float(nu[0]), float(nu[1]), S, d, accept, reset))
            if accept:
                rejected_run[sensor] = 0
                S = P[:2, :2] + sigma**2 * np.eye(2)
                gain = np.linalg.solve(S, P[:2, :]).T
                x = x + gain @ nu
                A = eye.copy()
                A[:, :2] -= gain
                P = A @ P @ A.T + sigma**2 * gain @ gain.T  # Joseph form
        P = 0.5 * (P + P.T)
        xf[k], Pf[k] = x, P

    xs, Ps = _rts(xf, Pf, xp, Pp, F_all)
    n_rejected = sum(1 for row in log_rows if not row[6])
    if n_rejected:
        log.warning("filter: %d of %d position fixes rejected by the gate", n_rejected, len(log_rows))
    smoothed, heading_error = _densify(
        inputs, T, (C, L, W), (CT, LT, WT), (D_dvl, D_lever, D_weighted), xs, Ps
    )
    return FilterResult(
        smoothed=smoothed,
        innovations=_innovations(log_rows),
        heading_error_rad=heading_error,
        dvl_scale_error=float(xs[0, _KAPPA]),
        dvl_scale_sigma=float(math.sqrt(Ps[0, _KAPPA, _KAPPA])),
        deviation_rad=xs[0, dev].copy(),
        deviation_sigma_rad=np.sqrt(np.diagonal(Ps[0])[dev]),
    )


def _rts(
    xf: FloatArray, Pf: FloatArray, xp: FloatArray, Pp: FloatArray, F: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Rauch-Tung-Striebel: ``G_k = Pf_k F_k^T Pp_{k+1}^-1``, then the backward recursion."""
    K = len(xf)
    xs, Ps = xf.copy(), Pf.copy()
    if K < 2:
        return xs, Ps
    # G_k^T = Pp_{k+1}^-1 F_k Pf_k (Pp and Pf symmetric).
    G = np.swapaxes(np.linalg.solve(Pp[1:], F @ Pf[:-1]), 1, 2)
    for k in range(K - 2, -1, -1):
        g = G[k]
        xs[k] = xf[k] + g @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + g @ (Ps[k + 1] - Pp[k + 1]) @ g.T
    return xs, Ps


def _densify(
    inputs: NavInputs,
    T: FloatArray,
    at_samples: tuple[FloatArray, FloatArray, FloatArray],
    at_epochs: tuple[FloatArray, FloatArray, FloatArray],
    over_intervals: tuple[FloatArray, FloatArray, FloatArray],
    xs: FloatArray,
    Ps: FloatArray,
) -> tuple[Trajectory, FloatArray]:
    """The smoothed epochs carried onto every sample (see the module docstring).

    ``at_samples``, ``at_epochs`` and ``over_intervals`` hold the cumulative DVL displacement, lever
    arm and harmonic-weighted displacement at the samples, at the epochs, and their changes over each
    interval. Returns the track and the heading correction at every sample.
    """
    t = inputs.t_s
    C, L, W = at_samples
    CT, LT, WT = at_epochs
    dev = slice(_HARMONICS0, xs.shape[1])
    k = np.clip(np.searchsorted(T, t, side="right") - 1, 0, len(T) - 2)
    phi = ((t - T[k]) / (T[k + 1] - T[k]))[:, None]
    partial = _move(xs[k, _BETA], xs[k, _KAPPA], xs[k, dev], C - CT[k], -(L - LT[k]), W - WT[k])
    whole = _move(xs[:-1, _BETA], xs[:-1, _KAPPA], xs[:-1, dev], *over_intervals)
    residual = xs[1:, :3] - xs[:-1, :3] - whole
    p = xs[k, :3] + partial + phi * residual[k]

    # Heading correction beta + sum c_m phi_m(h) and its sigma, from the state's heading block.
    n_harmonics = (xs.shape[1] - _HARMONICS0) // 2
    basis = np.concatenate([np.ones((len(t), 1)), _harmonics(inputs.compass_heading_rad, n_harmonics)], 1)
    heading_states = [_BETA, *range(dev.start, dev.stop)]
    coefficients = interp_rows(t, T, xs[:, heading_states])
    heading_error = np.einsum("ni,ni->n", basis, coefficients)
    block = Ps[np.ix_(np.arange(len(T)), heading_states, heading_states)]
    var_heading = np.einsum("ni,nij,nj->n", basis, block[k], basis)
    sd = np.sqrt(interp_rows(t, T, np.diagonal(Ps, axis1=1, axis2=2)[:, :3]))
    trajectory = Trajectory(
        t_s=t,
        p_ned_m=p,
        roll_rad=inputs.roll_rad,
        pitch_rad=inputs.pitch_rad,
        yaw_rad=wrap_angle(inputs.yaw_rad + heading_error),
        sigma_ned_m=sd,
        sigma_yaw_rad=np.sqrt(np.maximum(var_heading, 0.0)),
    )
    return trajectory, heading_error


def _innovations(rows: list[tuple[float, str, float, float, FloatArray, float, bool, bool]]) -> Innovations:
    m = len(rows)
    return Innovations(
        t_s=np.array([r[0] for r in rows], dtype=float),
        sensor=np.array([r[1] for r in rows], dtype=str).reshape(m),
        nu_ne_m=np.array([[r[2], r[3]] for r in rows], dtype=float).reshape(m, 2),
        S_ne_m2=np.array([r[4] for r in rows], dtype=float).reshape(m, 2, 2),
        mahalanobis=np.array([r[5] for r in rows], dtype=float),
        accepted=np.array([r[6] for r in rows], dtype=bool),
        reset=np.array([r[7] for r in rows], dtype=bool),
    )
