"""The tide from loop closures alone: a harmonic fit to their vertical residuals (issue 8, part 4).

A loop closure between images at ``t_i`` and ``t_j`` measures the false depth change
``r = [d_p(t_j) - d_p(t_i)] - [z(t_j) - z(t_i)] = eta(t_j) - eta(t_i) + noise`` (signs and physics in
:mod:`auvnav.depth.validation`). The tide enters only through differences, so its mean (the datum
offset, Z0) is not observable; everything that varies over the dive is.

Model
-----
``eta(t) = sum_k x_k C_k(t) + y_k S_k(t)``, where ``C_k`` and ``S_k`` are the predictions of
constituent ``k`` with unit amplitude and Greenwich phase lag 0 and 90 degrees, made by the same utide
machinery as :meth:`auvnav.depth.tide.TideModel.predict` (astronomical argument ``V + u`` and nodal
factor ``f`` at the exact times). Since ``A f cos(V + u - g) = A cos(g) f cos(V + u) + A sin(g) f sin(V + u)``,
``(x_k, y_k) = A_k (cos g_k, sin g_k)`` and the fit is an ordinary :class:`~auvnav.depth.tide.TideModel`
(with ``mean_m = 0``). The unit predictions are evaluated on a 600 s grid and interpolated by a
cubic spline, which errs by at most ``5 (omega h)^4 / 384 < 1e-6`` of the amplitude for the fastest
candidate (K2, ``omega = 1.46e-4 rad/s``).

Each loop gives one row ``[C_k(t_j) - C_k(t_i), S_k(t_j) - S_k(t_i), ...]`` of the design matrix
``A``. The loops are not independent: every loop with an image at a given time shares the error of
the pressure depth there, and a navigation check that revisits one place a dozen times yields
hundreds of loops but only a dozen independent looks at the tide. Ordinary weighted least squares
then quotes uncertainties several times too small (the tests saw a factor of about 7). The fit is
therefore generalised least squares with the error model ``d = A x + D e + v``: ``v`` the loop's own
error (the visual vertical change, 1-sigma ``sigma_m``), ``e`` one shared error per time bin of the
pressure fit's window (1-sigma: the pressure depth's, RMS over the images in the bin), ``D`` the
incidence of the loops' ends in the bins. ``x`` and ``e`` are solved together from their normal
equations (``e`` with its prior), and the covariance of ``x`` is its block of the inverse normal
matrix, scaled by the reduced chi-square so that it follows the scatter actually seen.

Which constituents
------------------
Candidates: the eight principal constituents M2, K1, S2, O1, N2, K2, P1, Q1 (Pugh, D. T. (1987),
*Tides, Surges and Mean Sea-Level*, Wiley, chapter 4), semidiurnal and diurnal band leaders first.
The record length ``T`` (first to last image of the loops) decides what can be fitted, by the
Rayleigh criterion (Godin, G. (1972), *The Analysis of Tides*, University of Toronto Press; as in
T_TIDE, Pawlowicz et al. 2002, and UTide): two frequencies are told apart when ``|f_a - f_b| T >= R``,
``R = 1``. Candidates closer than ``R / T`` to a neighbour form a group (single linkage over
frequency); one sinusoid is fitted per group, at the frequency of its first candidate, and carries
the signal of the others (:attr:`EstimatedConstituent.absorbed`). A fitted constituent is *resolved*
(its amplitude and phase are harmonic constants of the site) when the record also separates it from
every other candidate and from the unobservable mean (``f T >= R``).

A 3 to 6 hour dive resolves none: M2 alone needs 12.4 h, M2 from K1 25.8 h, M2 from S2 355 h. All
eight candidates then form one group and the fit is a single *effective* semidiurnal sinusoid at the
M2 frequency. Over a few hours that follows the sum of the constituents to a centimetre or so (the
tests measure it); its amplitude and phase are not the site's harmonic constants, but the tide
*change* over the dive is well determined, and :meth:`TideEstimate.change_sigma_m` gives its
uncertainty. Fitting more sinusoids than the record resolves gives nearly collinear columns whose
coefficients run to absurd values while fitting the noise.

Loops whose residual exceeds :data:`OUTLIER_SIGMAS` times ``max(1, robust scale)`` sigmas (robust
scale: 1.4826 x the median absolute normalised residual) are set aside and the fit repeated until the
set is stable; they are counted in a warning.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.interpolate import CubicSpline
from utide._ut_constants import constit_index_dict, ut_constants

from auvnav.depth.tide import Constituent, TideModel
from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray

log = logging.getLogger(__name__)

CANDIDATES: tuple[str, ...] = ("M2", "K1", "S2", "O1", "N2", "K2", "P1", "Q1")
"""Constituents considered, band leaders first: each Rayleigh group is fitted at the frequency of its
first member in this order."""

RAYLEIGH: float = 1.0
"""Rayleigh criterion R, cycles: two frequencies are resolved when their difference times the record
length is at least R (T_TIDE's and UTide's default)."""

OUTLIER_SIGMAS: float = 5.0
"""A loop whose residual exceeds this many (robustly scaled) sigmas is set aside as an outlier."""

_GRID_S = 600.0  # step of the grid the unit predictions are evaluated on (module docstring)
_MAX_ITERATIONS = 10


def frequency_cph(name: str) -> float:
    """Frequency of a constituent in utide's table, cycles per hour."""
    if name not in constit_index_dict:
        raise ValueError(f"constituent {name!r} is not in utide's table")
    return float(ut_constants.const.freq[constit_index_dict[name]])


def resolving_record_s(name: str, others: tuple[str, ...] = CANDIDATES) -> float:
    """The record length that resolves ``name`` from the mean and from each of ``others`` (Rayleigh), s.

    ``R / min(f, |f - f_m|)`` over the other constituents ``m``, with ``R`` = :data:`RAYLEIGH`.
    """
    f = frequency_cph(name)
    gaps = [f] + [abs(f - frequency_cph(m)) for m in others if m != name]
    return RAYLEIGH / min(gaps) * 3600.0


@dataclass(frozen=True)
class EstimatedConstituent:
    """One fitted constituent with its 1-sigma uncertainties.

    Parameters
    ----------
    name : str
    amplitude_m, amplitude_sigma_m : float
        Amplitude and its 1-sigma, metres.
    phase_rad, phase_sigma_rad : float
        Greenwich phase lag in [0, 2 pi) and its 1-sigma, radians (linearised; large when the
        amplitude is not significant).
    resolved : bool
        Whether the record resolves it from the mean and every other candidate (Rayleigh); when not,
        it is an effective sinusoid that absorbs its unresolved neighbours.
    resolving_record_s : float
        The record length that would resolve it, seconds.
    absorbed : tuple of str
        The candidates the record cannot tell from it (its Rayleigh group), whose signal it carries.
    """

    name: str
    amplitude_m: float
    amplitude_sigma_m: float
    phase_rad: float
    phase_sigma_rad: float
    resolved: bool
    resolving_record_s: float
    absorbed: tuple[str, ...] = ()


@dataclass(frozen=True)
class TideEstimate:
    """A tide fitted to loop-closure vertical residuals.

    Parameters
    ----------
    model : TideModel
        The fitted constituents, ``mean_m = 0`` (the mean is unobservable).
    constituents : tuple of EstimatedConstituent
        The same constituents with uncertainties and Rayleigh flags.
    covariance_m2 : ndarray, shape (2K, 2K), m^2
        Covariance of ``(x_1, y_1, x_2, y_2, ...)``, ``x = A cos g``, ``y = A sin g``, scaled by the
        reduced chi-square.
    record_s : float
        First to last image time of the loops used, seconds.
    inlier : ndarray of bool, shape (N,)
        Which loops the fit used (the others are outliers).
    rms_fit_m : float
        RMS of the residual of the fitted tide changes over the inliers, metres.
    reduced_chi2 : float
        chi-square of the inliers per degree of freedom, with the sigmas given.
    """

    model: TideModel
    constituents: tuple[EstimatedConstituent, ...]
    covariance_m2: FloatArray
    record_s: float
    inlier: NDArray[np.bool_]
    rms_fit_m: float
    reduced_chi2: float

    def __post_init__(self) -> None:
        k = len(self.model.constituents)
        if len(self.constituents) != k:
            raise ValueError(f"constituents must match the model's {k}; found {len(self.constituents)}")
        if np.shape(self.covariance_m2) != (2 * k, 2 * k):
            raise ValueError(
                f"covariance_m2 must have shape ({2 * k}, {2 * k}); found {np.shape(self.covariance_m2)}"
            )

    @property
    def n_used(self) -> int:
        """Loops the fit used."""
        return int(np.count_nonzero(self.inlier))

    @property
    def n_outliers(self) -> int:
        """Loops set aside as outliers."""
        return int(self.inlier.size - self.n_used)

    def change_m(self, t_i_s: ArrayLike, t_j_s: ArrayLike) -> FloatArray:
        """The fitted tide change ``eta(t_j) - eta(t_i)``, metres; shape of the inputs."""
        return self.model.predict(t_j_s) - self.model.predict(t_i_s)

    def change_sigma_m(self, t_i_s: ArrayLike, t_j_s: ArrayLike) -> FloatArray:
        """1-sigma of :meth:`change_m` from the coefficient covariance, metres; shape of the inputs."""
        t_i = np.asarray(t_i_s, dtype=float)
        t_j = np.asarray(t_j_s, dtype=float)
        names = tuple(c.name for c in self.model.constituents)
        A = _difference_basis(names, t_i.ravel(), t_j.ravel(), self.model.latitude_rad)
        variance = np.einsum("ni,ij,nj->n", A, self.covariance_m2, A)
        return np.sqrt(np.maximum(variance, 0.0)).reshape(t_i.shape)


def _unit_predictions(names: tuple[str, ...], t_s: FloatArray, latitude_rad: float) -> FloatArray:
    """``[C_1, S_1, C_2, S_2, ...]`` at ``t_s``, shape (N, 2K): unit-amplitude predictions at Greenwich
    phase 0 and pi/2 (module docstring), by a cubic spline through a 600 s grid."""
    t0, t1 = float(t_s.min()), float(t_s.max())
    grid = t0 + _GRID_S * np.arange(-1, math.floor((t1 - t0) / _GRID_S) + 3)
    columns = []
    for name in names:
        for phase_rad in (0.0, 0.5 * math.pi):
            unit = TideModel((Constituent(name, 1.0, phase_rad),), latitude_rad)
            columns.append(CubicSpline(grid, unit.predict(grid))(t_s))
    return np.column_stack(columns)


def _difference_basis(
    names: tuple[str, ...], t_i_s: FloatArray, t_j_s: FloatArray, latitude_rad: float
) -> FloatArray:
    """Design matrix of tide changes, shape (N, 2K): basis at ``t_j`` minus basis at ``t_i``."""
    basis = _unit_predictions(names, np.concatenate([t_i_s, t_j_s]), latitude_rad)
    n = t_i_s.size
    return basis[n:] - basis[:n]


def _phase_rad(x: float, y: float) -> float:
    """The angle of ``(x, y)`` in [0, 2 pi)."""
    phase = math.atan2(y, x) % (2 * math.pi)
    return phase if phase < 2 * math.pi else 0.0


@dataclass(frozen=True)
class _SharedErrors:
    """Errors shared by the loops with an image in the same time bin: the incidence matrix ``D``
    (N, B), ``+1`` at the bin of ``t_j`` and ``-1`` at the bin of ``t_i`` (0 when both fall in one),
    and each bin's 1-sigma."""

    D: sparse.csr_matrix
    sigma_m: FloatArray

    @classmethod
    def build(
        cls, t_i: FloatArray, t_j: FloatArray, sigma_i: FloatArray, sigma_j: FloatArray, bin_s: float
    ) -> _SharedErrors:
        t0 = min(t_i.min(), t_j.min())
        bins = np.floor((np.concatenate([t_i, t_j]) - t0) / bin_s).astype(np.int64)
        used, column = np.unique(bins, return_inverse=True)
        n = t_i.size
        rows = np.concatenate([np.arange(n), np.arange(n)])
        signs = np.concatenate([-np.ones(n), np.ones(n)])
        D = sparse.csr_matrix((signs, (rows, column)), shape=(n, used.size))  # duplicates summed
        variance = np.bincount(column, np.concatenate([sigma_i, sigma_j]) ** 2) / np.bincount(column)
        return cls(D=D, sigma_m=np.sqrt(variance))


def _fit(
    A: FloatArray, d: FloatArray, sigma: FloatArray, shared: _SharedErrors | None
) -> tuple[FloatArray, FloatArray, float]:
    """Generalised least squares of ``d = A x + D e + v``, ``v ~ N(0, sigma^2)`` per loop and
    ``e ~ N(0, shared.sigma_m^2)`` per time bin, by the normal equations of ``(x, e)``.

    Returns
    -------
    x : ndarray, shape (P,)
    covariance : ndarray, shape (P, P)
        Unscaled covariance of ``x`` (the ``x`` block of the pseudo-inverse of the normal matrix).
    chi2 : float
        ``sum ((d - A x - D e) / sigma)^2 + sum (e / shared.sigma_m)^2``.
    """
    w = 1.0 / sigma**2
    p = A.shape[1]
    if shared is None:
        normal = A.T @ (w[:, None] * A)
        rhs = A.T @ (w * d)
    else:
        D = shared.D
        DtW = D.T.multiply(w[None, :]).tocsr()
        top = np.hstack([A.T @ (w[:, None] * A), (DtW @ A).T])
        bottom = np.hstack([DtW @ A, (DtW @ D).toarray() + np.diag(1.0 / shared.sigma_m**2)])
        normal = np.vstack([top, bottom])
        rhs = np.concatenate([A.T @ (w * d), DtW @ d])
    inverse = np.linalg.pinv(normal, rcond=1e-12, hermitian=True)
    solution = inverse @ rhs
    x = solution[:p]
    shared_m = np.zeros_like(d) if shared is None else shared.D @ solution[p:]
    chi2 = float(np.sum(w * (d - A @ x - shared_m) ** 2))
    if shared is not None:
        chi2 += float(np.sum((solution[p:] / shared.sigma_m) ** 2))
    return x, inverse[:p, :p], chi2


def rayleigh_groups(candidates: tuple[str, ...], record_s: float) -> list[tuple[str, ...]]:
    """Candidates grouped so that a record of ``record_s`` seconds cannot tell apart two members.

    Single linkage over frequency: neighbours closer than ``R / T`` (the Rayleigh criterion,
    :data:`RAYLEIGH`) share a group. Each group lists its members in the order of ``candidates``; the
    groups come in the order of their first members.
    """
    if not record_s > 0:
        raise ValueError(f"record_s must be positive; found {record_s!r}")
    resolution_cph = RAYLEIGH / (record_s / 3600.0)
    by_frequency = sorted(candidates, key=frequency_cph)
    groups = [[by_frequency[0]]]
    for previous, name in itertools.pairwise(by_frequency):
        if frequency_cph(name) - frequency_cph(previous) < resolution_cph:
            groups[-1].append(name)
        else:
            groups.append([name])
    order = {name: k for k, name in enumerate(candidates)}
    ordered = [tuple(sorted(g, key=order.__getitem__)) for g in groups]
    return sorted(ordered, key=lambda g: order[g[0]])


def estimate_tide(
    t_i_s: ArrayLike,
    t_j_s: ArrayLike,
    change_m: ArrayLike,
    sigma_m: ArrayLike,
    latitude_rad: float,
    *,
    shared_sigma_i_m: ArrayLike | None = None,
    shared_sigma_j_m: ArrayLike | None = None,
    shared_bin_s: float = 60.0,
    candidates: tuple[str, ...] = CANDIDATES,
) -> TideEstimate:
    """Fit a tide to observed tide changes between pairs of times (module docstring).

    Parameters
    ----------
    t_i_s, t_j_s : array_like, shape (N,), seconds since the POSIX epoch, UTC
        Times of the first and second image of each loop closure.
    change_m : array_like, shape (N,), metres
        Observed ``eta(t_j) - eta(t_i)``: the loops' vertical residuals before any tide correction.
    sigma_m : array_like, shape (N,), metres
        1-sigma of each loop's own error (the visual vertical change), > 0.
    latitude_rad : float
        Latitude of the site, radians (nodal corrections).
    shared_sigma_i_m, shared_sigma_j_m : array_like, shape (N,), metres, optional
        1-sigma of the errors at each end that loops share (the pressure depth at an image time, the
        same for every loop with an image in the same ``shared_bin_s`` time bin); both or neither.
    shared_bin_s : float
        Width of those time bins, seconds (the pressure fit's window).
    candidates : tuple of str
        Constituents to consider (module docstring), band leaders first.

    Returns
    -------
    TideEstimate

    Raises
    ------
    InsufficientDataError
        Fewer than three loop closures.
    """
    t_i = np.asarray(t_i_s, dtype=float)
    t_j = np.asarray(t_j_s, dtype=float)
    d = np.asarray(change_m, dtype=float)
    sigma = np.asarray(sigma_m, dtype=float)
    if not (t_i.ndim == 1 and t_i.shape == t_j.shape == d.shape == sigma.shape):
        raise ValueError(
            f"t_i_s, t_j_s, change_m and sigma_m must be 1-D and match; found "
            f"{t_i.shape}, {t_j.shape}, {d.shape} and {sigma.shape}"
        )
    if not (np.all(np.isfinite(t_i)) and np.all(np.isfinite(t_j)) and np.all(np.isfinite(d))):
        raise ValueError("t_i_s, t_j_s and change_m must be finite")
    if not np.all(sigma > 0):
        raise ValueError("sigma_m must be positive and finite")
    if (shared_sigma_i_m is None) != (shared_sigma_j_m is None):
        raise ValueError("give both shared_sigma_i_m and shared_sigma_j_m, or neither")
    shared_i = np.zeros_like(d) if shared_sigma_i_m is None else np.asarray(shared_sigma_i_m, dtype=float)
    shared_j = np.zeros_like(d) if shared_sigma_j_m is None else np.asarray(shared_sigma_j_m, dtype=float)
    if shared_i.shape != d.shape or shared_j.shape != d.shape:
        raise ValueError(
            f"shared sigmas must match change_m {d.shape}; found {shared_i.shape} and {shared_j.shape}"
        )
    if shared_sigma_i_m is not None and not (np.all(shared_i > 0) and np.all(shared_j > 0)):
        raise ValueError("shared sigmas must be positive and finite")
    if not shared_bin_s > 0:
        raise ValueError(f"shared_bin_s must be positive; found {shared_bin_s!r}")
    if not candidates:
        raise ValueError("candidates must name at least one constituent")
    if d.size < 3:
        raise InsufficientDataError(f"estimating the tide needs at least 3 loop closures; found {d.size}")

    record_s = float(max(t_i.max(), t_j.max()) - min(t_i.min(), t_j.min()))
    if not record_s > 0:
        raise InsufficientDataError("estimating the tide needs loop closures at different times")
    groups = rayleigh_groups(tuple(candidates), record_s)
    names = tuple(g[0] for g in groups)
    A = _difference_basis(names, t_i, t_j, latitude_rad)
    k = len(names)
    total_sigma = np.sqrt(sigma**2 + shared_i**2 + shared_j**2)

    def fit(inlier: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray, float]:
        shared = None
        if shared_sigma_i_m is not None:
            shared = _SharedErrors.build(
                t_i[inlier], t_j[inlier], shared_i[inlier], shared_j[inlier], shared_bin_s
            )
        return _fit(A[inlier], d[inlier], sigma[inlier], shared)

    inlier = np.ones(d.size, dtype=bool)
    for _ in range(_MAX_ITERATIONS):
        coef = fit(inlier)[0]
        z = (d - A @ coef) / total_sigma
        scale = max(1.0, 1.4826 * float(np.median(np.abs(z[inlier]))))
        updated = np.abs(z) <= OUTLIER_SIGMAS * scale
        if np.count_nonzero(updated) < 3 or np.array_equal(updated, inlier):
            break
        inlier = updated
    coef, covariance, chi2 = fit(inlier)
    n_used = int(np.count_nonzero(inlier))
    reduced_chi2 = chi2 / max(n_used - 2 * k, 1)
    covariance = covariance * reduced_chi2
    residual = d - A @ coef
    if n_used < d.size:
        log.warning(
            "tide estimate: %d of %d loop closures set aside as outliers (beyond %.0f sigma)",
            d.size - n_used,
            d.size,
            OUTLIER_SIGMAS,
        )

    fitted = []
    for m, (name, *absorbed) in enumerate(groups):
        x, y = coef[2 * m], coef[2 * m + 1]
        amplitude = math.hypot(x, y)
        C = covariance[2 * m : 2 * m + 2, 2 * m : 2 * m + 2]
        if amplitude > 0:
            J_a = np.array([x, y]) / amplitude
            J_g = np.array([-y, x]) / amplitude**2
            amplitude_sigma = math.sqrt(max(J_a @ C @ J_a, 0.0))
            phase_sigma = min(math.sqrt(max(J_g @ C @ J_g, 0.0)), math.pi)
        else:
            amplitude_sigma, phase_sigma = math.sqrt(max(np.trace(C) / 2, 0.0)), math.pi
        needed_s = resolving_record_s(name, tuple(candidates))
        fitted.append(
            EstimatedConstituent(
                name=name,
                amplitude_m=amplitude,
                amplitude_sigma_m=amplitude_sigma,
                phase_rad=_phase_rad(x, y),
                phase_sigma_rad=phase_sigma,
                resolved=record_s >= needed_s,
                resolving_record_s=needed_s,
                absorbed=tuple(absorbed),
            )
        )
    model = TideModel(
        tuple(Constituent(c.name, c.amplitude_m, c.phase_rad) for c in fitted),
        latitude_rad,
        reference=(
            f"auvnav estimate from {n_used} loop-closure vertical residuals over {record_s / 3600:.2f} h; "
            f"mean level unobservable; resolved (Rayleigh): "
            f"{', '.join(c.name for c in fitted if c.resolved) or 'none'}"
        ),
        mean_m=0.0,
    )
    return TideEstimate(
        model=model,
        constituents=tuple(fitted),
        covariance_m2=covariance,
        record_s=record_s,
        inlier=inlier,
        rms_fit_m=float(np.sqrt(np.mean(residual[inlier] ** 2))),
        reduced_chi2=reduced_chi2,
    )
