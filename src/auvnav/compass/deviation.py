"""The compass deviation model and its least-squares fit (paper eq. 5-6).

The correction to a measured compass heading ``h`` is a truncated Fourier series (eq. 5),

    delta(h) = a0 + sum_{k=1..N} a_k cos(k h) + b_k sin(k h),

and the corrected heading is ``h + delta(h)``. Given reference headings ``h_ref`` (from SLAM, or the
truth in simulation) at the times of compass headings ``h``, the coefficients solve ``A x = b``
(eq. 6) with rows ``[1, cos h, sin h, ..., cos N h, sin N h]`` and ``b = wrap(h_ref - h)`` by linear
least squares, optionally made robust by iteratively reweighted least squares with Huber weights
(Huber, "Robust Statistics", Wiley 1981, ch. 7), so a few bad poses cannot bend the curve.

The constant ``a0`` is unobservable from relative (visual) constraints: the paper fixes it afterwards
from GPS course made good on long sub-sea transits, holding the shape (:func:`fix_constant`).

Coefficient vectors and covariances are ordered as the paper's ``x = [a0, a1, b1, ..., aN, bN]``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike

from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray, wrap_angle

log = logging.getLogger(__name__)

ConstantSource = Literal["arbitrary", "gps-transits", "truth", "graph"]
CONSTANT_SOURCES: tuple[str, ...] = get_args(ConstantSource)

# Huber's tuning constant: 95% efficiency at the normal distribution (Huber 1981, sec. 4.6).
HUBER_K = 1.345
# Median absolute deviation to standard deviation for normal residuals: 1 / Phi^-1(3/4).
MAD_TO_SIGMA = 1.482602218505602
# A residual beyond this many robust standard deviations is flagged as an outlier.
OUTLIER_SIGMAS = 3.0
_IRLS_MAX_ITERATIONS = 100
_IRLS_TOLERANCE_RAD = 1e-10
# Evaluation grid for the band inside heading gaps: 0.25 degree steps.
_GRID_STEP_RAD = math.radians(0.25)


def fourier_design(h_rad: ArrayLike, harmonics: int) -> FloatArray:
    """Rows ``[1, cos h, sin h, ..., cos N h, sin N h]`` of eq. 6; shape (..., 2N+1).

    Parameters
    ----------
    h_rad : array_like, radians
        Compass headings.
    harmonics : int
        N, the number of harmonics (>= 0).
    """
    h = np.asarray(h_rad, dtype=float)[..., None]
    k = np.arange(1, harmonics + 1, dtype=float)
    trig = np.stack([np.cos(k * h), np.sin(k * h)], axis=-1).reshape(*h.shape[:-1], 2 * harmonics)
    return np.concatenate([np.ones_like(h), trig], axis=-1)  # eq. 5-6


@dataclass(frozen=True)
class DeviationModel:
    """The compass correction of eq. 5, ``delta(h)``, with its uncertainty.

    Parameters
    ----------
    a0_rad : float
        Constant term, radians.
    a_rad, b_rad : ndarray, shape (N,), radians
        Cosine and sine coefficients of harmonics 1..N.
    covariance : ndarray, shape (2N+1, 2N+1), rad^2, or None
        Covariance of ``[a0, a1, b1, ..., aN, bN]``; None when unknown.
    constant_source : {"arbitrary", "gps-transits", "truth", "graph"}
        How ``a0`` was fixed: ``"arbitrary"`` from relative data only (the paper's SLAM fit),
        ``"gps-transits"`` by :func:`fix_constant`, ``"truth"`` from a simulation's truth,
        ``"graph"`` jointly in a pose graph with absolute fixes.
    """

    a0_rad: float
    a_rad: FloatArray
    b_rad: FloatArray
    covariance: FloatArray | None = None
    constant_source: ConstantSource = "arbitrary"

    def __post_init__(self) -> None:
        a = np.array(self.a_rad, dtype=float).reshape(-1)
        b = np.array(self.b_rad, dtype=float).reshape(-1)
        if a.shape != b.shape:
            raise ValueError(f"a_rad and b_rad must match; found {a.shape} and {b.shape}")
        if not (math.isfinite(self.a0_rad) and np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise ValueError("deviation coefficients must be finite")
        if self.constant_source not in CONSTANT_SOURCES:
            raise ValueError(
                f"constant_source must be one of {CONSTANT_SOURCES}; found {self.constant_source!r}"
            )
        object.__setattr__(self, "a0_rad", float(self.a0_rad))
        for name, value in (("a_rad", a), ("b_rad", b)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.covariance is not None:
            p = 2 * len(a) + 1
            cov = np.array(self.covariance, dtype=float)
            if cov.shape != (p, p):
                raise ValueError(f"covariance must have shape ({p}, {p}); found {cov.shape}")
            if not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
                raise ValueError("covariance must be finite and symmetric")
            cov.setflags(write=False)
            object.__setattr__(self, "covariance", cov)

    @classmethod
    def from_coefficients(
        cls,
        x_rad: ArrayLike,
        covariance: ArrayLike | None = None,
        constant_source: ConstantSource = "arbitrary",
    ) -> DeviationModel:
        """A model from the paper's coefficient vector ``x = [a0, a1, b1, ..., aN, bN]`` (radians)."""
        x = np.asarray(x_rad, dtype=float).reshape(-1)
        if x.size % 2 != 1:
            raise ValueError(f"coefficient vector must have odd length 2N+1; found {x.size}")
        cov = None if covariance is None else np.asarray(covariance, dtype=float)
        return cls(float(x[0]), x[1::2], x[2::2], cov, constant_source)

    @property
    def harmonics(self) -> int:
        """N, the number of harmonics."""
        return len(self.a_rad)

    @property
    def coefficients_rad(self) -> FloatArray:
        """``x = [a0, a1, b1, ..., aN, bN]``, radians; shape (2N+1,)."""
        x = np.empty(2 * self.harmonics + 1)
        x[0], x[1::2], x[2::2] = self.a0_rad, self.a_rad, self.b_rad
        return x

    def __call__(self, h_rad: ArrayLike) -> FloatArray:
        """``delta(h)`` (eq. 5), radians, for compass headings ``h_rad`` (any shape)."""
        return fourier_design(h_rad, self.harmonics) @ self.coefficients_rad

    def correct(self, h_rad: ArrayLike) -> FloatArray:
        """Corrected heading ``wrap(h + delta(h))``, radians in (-pi, pi]."""
        return wrap_angle(np.asarray(h_rad, dtype=float) + self(h_rad))

    def sigma(self, h_rad: ArrayLike) -> FloatArray:
        """1-sigma uncertainty of ``delta(h)`` from the covariance, radians; NaN without one."""
        phi = fourier_design(h_rad, self.harmonics)
        if self.covariance is None:
            return np.full(phi.shape[:-1], np.nan)
        return np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", phi, self.covariance, phi), 0.0))


@dataclass(frozen=True)
class DeviationFit:
    """A deviation fit (eq. 6) with its diagnostics.

    Parameters
    ----------
    model : DeviationModel
        The fitted correction.
    compass_heading_rad : ndarray, shape (M,), radians
        The compass headings given (NaN where a pair was unusable).
    observed_rad : ndarray, shape (M,), radians
        ``wrap(reference - compass)``, the left-hand side ``b`` of eq. 6.
    residuals_rad : ndarray, shape (M,), radians
        ``observed - delta(compass)``; NaN where a pair was unusable.
    inlier : ndarray of bool, shape (M,)
        Residual within ``OUTLIER_SIGMAS`` robust standard deviations (False for unusable pairs).
    residual_rms_rad : float
        RMS of the inlier residuals.
    scale_rad : float
        Residual standard deviation: robust (MAD) with ``robust=True``, else from the residual sum
        of squares.
    cv_harmonics : int or None
        The number of harmonics chosen by cross-validation (one-standard-error rule), None when
        there are too few samples to cross-validate.
    cv_rms_rad : dict of int to float
        Cross-validated RMS error (inlier held-out samples) for each number of harmonics tried.
    gaps : list of (float, float)
        Heading sectors with no sample wider than the gap threshold, as (start, end) compass
        headings in radians, clockwise from start to end.
    gap_sigma_rad : list of float
        Largest 1-sigma band inside each gap, radians.
    robust : bool
        Whether Huber weights were used.
    """

    model: DeviationModel
    compass_heading_rad: FloatArray
    observed_rad: FloatArray
    residuals_rad: FloatArray
    inlier: np.ndarray
    residual_rms_rad: float
    scale_rad: float
    cv_harmonics: int | None
    cv_rms_rad: dict[int, float] = field(default_factory=dict)
    gaps: list[tuple[float, float]] = field(default_factory=list)
    gap_sigma_rad: list[float] = field(default_factory=list)
    robust: bool = True

    def __post_init__(self) -> None:
        shapes = {
            a.shape for a in (self.compass_heading_rad, self.observed_rad, self.residuals_rad, self.inlier)
        }
        if len(shapes) != 1:
            raise ValueError(f"per-sample arrays must share one shape; found {sorted(shapes)}")
        if len(self.gaps) != len(self.gap_sigma_rad):
            raise ValueError(
                f"gaps and gap_sigma_rad must match; found {len(self.gaps)} and {len(self.gap_sigma_rad)}"
            )

    @property
    def n_samples(self) -> int:
        """Usable samples."""
        return int(np.sum(np.isfinite(self.residuals_rad)))

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary in degrees, for ``auvnav compass fit --json``."""
        return {
            "harmonics": self.model.harmonics,
            "cv_harmonics": self.cv_harmonics,
            "n_samples": self.n_samples,
            "n_outliers": self.n_samples - int(np.sum(self.inlier)),
            "residual_rms_deg": math.degrees(self.residual_rms_rad),
            "a0_deg": math.degrees(self.model.a0_rad),
            "a_deg": np.degrees(self.model.a_rad).tolist(),
            "b_deg": np.degrees(self.model.b_rad).tolist(),
            "gaps_deg": [[math.degrees(s) % 360.0, math.degrees(e) % 360.0] for s, e in self.gaps],
            "gap_sigma_deg": np.degrees(self.gap_sigma_rad).tolist(),
        }


@dataclass(frozen=True)
class _Solution:
    """Coefficients, their covariance, residuals (plain and whitened) and the residual scale."""

    x: FloatArray
    covariance: FloatArray | None
    residuals: FloatArray
    whitened: FloatArray
    scale: float

    @property
    def inlier(self) -> np.ndarray:
        """Whitened residual within ``OUTLIER_SIGMAS`` scales (all, for an exact fit)."""
        if self.scale == 0.0:
            return np.ones(self.whitened.shape, dtype=bool)
        return np.abs(self.whitened) <= OUTLIER_SIGMAS * self.scale


def _robust_scale(r: FloatArray) -> float:
    """Normal-consistent median absolute deviation of ``r``."""
    return float(MAD_TO_SIGMA * np.median(np.abs(r - np.median(r))))


def _lstsq(A: FloatArray, y: FloatArray) -> FloatArray:
    """Least squares ``min |A x - y|`` through the normal equations (minimum norm if singular).

    ``A`` is tall and thin (at most 2N+1 columns). The small ``p x p`` solve costs microseconds,
    where LAPACK's factorisation of the tall matrix can take tens of milliseconds when a threaded
    BLAS competes for busy cores, and the fit solves hundreds of times (robust iterations and
    cross-validation). Squaring the condition number is harmless for a design whose headings span
    the rose; where they do not, the fit's band says so.
    """
    return np.linalg.lstsq(A.T @ A, A.T @ y, rcond=None)[0]


def _solve(A: FloatArray, y: FloatArray, w: FloatArray, *, robust: bool, huber_k: float) -> _Solution:
    """Weighted (and optionally Huber-IRLS) least squares for eq. 6, with the covariance.

    Works on the system whitened by ``sqrt(w)``. The covariance is ``s^2 (A^T W A)^-1`` for plain
    least squares, and Huber's correction for M-estimators with the robust fit (Huber 1981,
    sec. 7.6; statsmodels' RLM "H1").
    """
    n, p = A.shape
    sw = np.sqrt(w)
    Aw, yw = A * sw[:, None], y * sw
    x = _lstsq(Aw, yw)
    e = yw - Aw @ x
    scale = _robust_scale(e) if robust else 0.0
    if scale > 0.0:
        for _ in range(_IRLS_MAX_ITERATIONS):
            wh = np.sqrt(np.minimum(1.0, huber_k * scale / np.maximum(np.abs(e), np.finfo(float).tiny)))
            x_new = _lstsq(Aw * wh[:, None], yw * wh)
            done = np.max(np.abs(x_new - x)) < _IRLS_TOLERANCE_RAD
            x = x_new
            e = yw - Aw @ x
            scale = _robust_scale(e)
            if done or scale == 0.0:
                break
    r = y - A @ x
    dof = n - p
    if dof <= 0:
        return _Solution(x, None, r, e, 0.0)
    AtA_inv = np.linalg.inv(Aw.T @ Aw)
    if scale > 0.0:
        u = e / scale
        psi = np.clip(u, -huber_k, huber_k)
        dpsi = (np.abs(u) <= huber_k).astype(float)
        m = dpsi.mean()
        K = 1.0 + (p / n) * dpsi.var() / m**2
        cov = K**2 * (psi @ psi) / dof * scale**2 / m**2 * AtA_inv
    else:
        scale = float(np.sqrt(e @ e / dof))
        cov = scale**2 * AtA_inv
    return _Solution(x, 0.5 * (cov + cov.T), r, e, scale)


def heading_gaps(h_rad: ArrayLike, max_gap_rad: float) -> list[tuple[float, float]]:
    """Sectors of the compass rose wider than ``max_gap_rad`` that hold no heading.

    Parameters
    ----------
    h_rad : array_like, shape (M,), radians
        Headings (NaN ignored).
    max_gap_rad : float
        Widest empty sector tolerated, radians.

    Returns
    -------
    list of (start, end)
        Clockwise from ``start`` to ``end`` (the bounding headings, wrapped to (-pi, pi]), widest
        first; the whole rose ``(-pi, pi)`` when there are no headings.
    """
    h = np.sort(np.mod(np.asarray(h_rad, dtype=float).reshape(-1), 2.0 * np.pi))
    h = h[np.isfinite(h)]
    if h.size == 0:
        return [(-np.pi, np.pi)]
    widths = np.diff(np.append(h, h[0] + 2.0 * np.pi))
    order = np.argsort(-widths, kind="stable")
    return [
        (float(wrap_angle(h[i])), float(wrap_angle(h[(i + 1) % h.size])))
        for i in order
        if widths[i] > max_gap_rad
    ]


def _gap_sigma(model: DeviationModel, start: float, end: float) -> float:
    """Largest 1-sigma band of ``model`` over the clockwise sector from ``start`` to ``end``."""
    width = np.mod(end - start, 2.0 * np.pi) or 2.0 * np.pi
    grid = start + np.linspace(0.0, width, max(int(width / _GRID_STEP_RAD), 2) + 1)
    return float(np.max(model.sigma(grid)))


def _cross_validate(
    h: FloatArray,
    y: FloatArray,
    w: FloatArray,
    *,
    max_harmonics: int,
    folds: int,
    robust: bool,
    huber_k: float,
) -> tuple[dict[int, float], int | None]:
    """K-fold cross-validation of the number of harmonics.

    Samples are assigned to folds in turn; numbers of harmonics the headings cannot determine (a
    rank-deficient design) are not tried. The score is the mean squared held-out error over the
    samples the full fit keeps as inliers. Returns the RMS per number of harmonics and the choice
    by the one-standard-error rule (the fewest harmonics whose score is within one standard error
    of the best; Hastie, Tibshirani and Friedman, "The Elements of Statistical Learning", 2nd ed.,
    sec. 7.10.1), or None when the folds are too small for one harmonic.
    """
    n = len(h)
    fold = np.arange(n) % folds
    train_n = n - np.bincount(fold, minlength=folds).max()
    mse: dict[int, float] = {}
    se: dict[int, float] = {}
    for harmonics in range(1, max_harmonics + 1):
        if 2 * harmonics + 1 >= train_n:
            break
        A = fourier_design(h, harmonics)
        if np.linalg.matrix_rank(A) < 2 * harmonics + 1:  # the headings flown cannot determine them
            break
        errors = np.empty(n)
        for k in range(folds):
            test = fold == k
            sol = _solve(A[~test], y[~test], w[~test], robust=robust, huber_k=huber_k)
            errors[test] = y[test] - A[test] @ sol.x
        keep = _solve(A, y, w, robust=robust, huber_k=huber_k).inlier
        per_fold = [np.mean(errors[keep & (fold == k)] ** 2) for k in range(folds) if keep[fold == k].any()]
        mse[harmonics] = float(np.mean(errors[keep] ** 2))
        se[harmonics] = float(np.std(per_fold, ddof=1) / np.sqrt(len(per_fold))) if len(per_fold) > 1 else 0.0
    if not mse:
        return {}, None
    best = min(mse, key=lambda k: mse[k])
    choice = min(k for k in mse if mse[k] <= mse[best] + se[best])
    return {k: math.sqrt(v) for k, v in mse.items()}, choice


def fit_deviation(
    compass_heading_rad: ArrayLike,
    reference_heading_rad: ArrayLike,
    *,
    harmonics: int = 3,
    robust: bool = True,
    weights: ArrayLike | None = None,
    max_gap_rad: float | None = None,
    cv_max_harmonics: int = 6,
    cv_folds: int = 10,
    huber_k: float = HUBER_K,
    constant_source: ConstantSource = "arbitrary",
) -> DeviationFit:
    """Fit the compass correction ``delta(h)`` of eq. 5 by least squares (eq. 6).

    Parameters
    ----------
    compass_heading_rad : array_like, shape (M,), radians
        Measured compass headings ``h_nav``.
    reference_heading_rad : array_like, shape (M,), radians
        Reference headings ``h_im`` at the same times (SLAM, or truth in simulation), in the same
        north reference as the compass.
    harmonics : int
        N, the number of harmonics (the paper uses 3).
    robust : bool
        Iteratively reweighted least squares with Huber weights (``huber_k`` robust standard
        deviations), so gross outliers barely move the fit.
    weights : array_like, shape (M,), optional
        Relative weights of the pairs (e.g. inverse heading variances); default equal.
    max_gap_rad : float, optional
        A heading sector wider than this with no sample is reported (and warned about) as a gap.
        Default ``pi / harmonics``: half the period of the highest harmonic.
    cv_max_harmonics : int
        Largest number of harmonics tried by cross-validation.
    cv_folds : int
        Folds of the cross-validation (samples assigned in turn; >= 2).
    huber_k : float
        Huber tuning constant, in robust standard deviations.
    constant_source : str
        How the constant is fixed by this reference (see :class:`DeviationModel`).

    Returns
    -------
    DeviationFit

    Raises
    ------
    InsufficientDataError
        Fewer usable pairs than unknowns (2N+1), or headings too few to determine N harmonics.
    """
    h_all = np.asarray(compass_heading_rad, dtype=float)
    ref_all = np.asarray(reference_heading_rad, dtype=float)
    if h_all.ndim != 1 or h_all.shape != ref_all.shape:
        raise ValueError(
            f"compass and reference headings must be 1-D and match; found {h_all.shape} and {ref_all.shape}"
        )
    if harmonics < 0 or cv_folds < 2:
        raise ValueError(f"need harmonics >= 0 and cv_folds >= 2; found {harmonics} and {cv_folds}")
    w_all = np.ones_like(h_all) if weights is None else np.asarray(weights, dtype=float)
    if w_all.shape != h_all.shape or np.any(w_all < 0):
        raise ValueError(f"weights must be non-negative with shape {h_all.shape}")
    usable = np.isfinite(h_all) & np.isfinite(ref_all) & np.isfinite(w_all) & (w_all > 0)
    if not usable.all():
        log.warning(
            "deviation fit: ignoring %d of %d pairs (NaN heading or zero weight)",
            np.sum(~usable),
            usable.size,
        )
    h, w = h_all[usable], w_all[usable]
    y = wrap_angle(ref_all[usable] - h)
    p = 2 * harmonics + 1
    if h.size < p:
        raise InsufficientDataError(
            f"a deviation fit with {harmonics} harmonics has {p} unknowns but only "
            f"{h.size} usable heading pairs"
        )
    A = fourier_design(h, harmonics)  # eq. 5-6
    rank = np.linalg.matrix_rank(A)
    if rank < p:
        raise InsufficientDataError(
            f"the headings flown determine only {rank} of the {p} unknowns of a "
            f"{harmonics}-harmonic deviation fit: fly more headings or fit fewer harmonics"
        )
    sol = _solve(A, y, w, robust=robust, huber_k=huber_k)
    if sol.covariance is None:
        log.warning("deviation fit: as many unknowns as samples; no uncertainty estimate")
    model = DeviationModel.from_coefficients(sol.x, sol.covariance, constant_source)

    residuals = np.full(h_all.shape, np.nan)
    residuals[usable] = sol.residuals
    inlier = np.zeros(h_all.shape, dtype=bool)
    inlier[usable] = sol.inlier
    observed = np.full(h_all.shape, np.nan)
    observed[usable] = y
    rms = float(np.sqrt(np.mean(residuals[inlier] ** 2))) if inlier.any() else math.nan
    if inlier.sum() < usable.sum():
        log.info("deviation fit: %d of %d pairs flagged as outliers", usable.sum() - inlier.sum(), h.size)

    cv_rms, cv_harmonics = _cross_validate(
        h, y, w, max_harmonics=cv_max_harmonics, folds=cv_folds, robust=robust, huber_k=huber_k
    )

    threshold = math.pi / max(harmonics, 1) if max_gap_rad is None else max_gap_rad
    gaps = heading_gaps(h, threshold)
    gap_sigma = [_gap_sigma(model, s, e) for s, e in gaps]
    for (s, e), sig in zip(gaps, gap_sigma, strict=True):
        log.warning(
            "deviation fit: no compass headings between %.0f and %.0f deg (%.0f deg wide); "
            "the 1-sigma band there reaches %.2f deg",
            math.degrees(s) % 360.0,
            math.degrees(e) % 360.0,
            math.degrees(np.mod(e - s, 2.0 * np.pi)),
            math.degrees(sig),
        )
    return DeviationFit(
        model=model,
        compass_heading_rad=np.where(usable, h_all, np.nan),
        observed_rad=observed,
        residuals_rad=residuals,
        inlier=inlier,
        residual_rms_rad=rms,
        scale_rad=sol.scale,
        cv_harmonics=cv_harmonics,
        cv_rms_rad=cv_rms,
        gaps=gaps,
        gap_sigma_rad=gap_sigma,
        robust=robust,
    )


def _transit_rows(
    compass_heading_rad: ArrayLike | Sequence[ArrayLike],
    heading_weights: Sequence[ArrayLike] | None,
    harmonics: int,
) -> FloatArray:
    """The harmonic part of eq. 6's rows for each transit, shape (T, 2N).

    One heading per transit gives its row; headings along each transit with weights give the
    weighted mean of their rows (weights normalised per transit).
    """
    if heading_weights is None:
        h = np.asarray(compass_heading_rad, dtype=float).reshape(-1)
        if not np.all(np.isfinite(h)):
            raise ValueError("transit headings must be finite")
        return fourier_design(h, harmonics)[:, 1:]
    headings = list(compass_heading_rad)  # type: ignore[arg-type]
    if len(headings) != len(heading_weights):
        raise ValueError(
            f"headings and heading_weights must list the same transits; found {len(headings)} "
            f"and {len(heading_weights)}"
        )
    rows = []
    for i, (h_leg, w_leg) in enumerate(zip(headings, heading_weights, strict=True)):
        h = np.asarray(h_leg, dtype=float).reshape(-1)
        w = np.asarray(w_leg, dtype=float).reshape(-1)
        if h.shape != w.shape or h.size == 0:
            raise ValueError(f"transit {i}: headings and weights must match; found {h.shape} and {w.shape}")
        if not (np.all(np.isfinite(h)) and np.all(np.isfinite(w))) or w.sum() <= 0:
            raise ValueError(f"transit {i}: headings and weights must be finite with a positive sum")
        rows.append((w / w.sum()) @ fourier_design(h, harmonics)[:, 1:])
    return np.array(rows).reshape(len(rows), 2 * harmonics)


def transit_deviation(
    model: DeviationModel,
    compass_heading_rad: ArrayLike | Sequence[ArrayLike],
    heading_weights: Sequence[ArrayLike] | None = None,
) -> FloatArray:
    """The correction each transit measures under ``model``, radians, shape (T,).

    ``a0 + s_i`` with ``s_i`` the harmonic part at the transit's heading, or its weighted mean
    along the transit (see :func:`fix_constant`, which takes the same heading arguments).
    """
    return (
        model.a0_rad
        + _transit_rows(compass_heading_rad, heading_weights, model.harmonics) @ (model.coefficients_rad[1:])
    )


def fix_constant(
    model: DeviationModel,
    compass_heading_rad: ArrayLike | Sequence[ArrayLike],
    cmg_minus_dr_course_rad: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    heading_weights: Sequence[ArrayLike] | None = None,
    common_sigma_rad: float = 0.0,
) -> DeviationModel:
    """Fix the constant ``a0`` from sub-sea transits, holding the shape (paper sec. III.B, Fig. 5b).

    On a transit flown at a steady compass heading ``h_i``, the GPS course made good minus the
    course dead-reckoned with the *uncorrected* compass (in the same north reference, declination
    applied) measures the full correction ``delta(h_i)``. With the harmonics held, the weighted
    least-squares constant is ``a0 = sum w_i (y_i - s_i) / sum w_i``, ``s_i = s(h_i)`` the harmonic
    part at the transit's heading.

    A transit that is not flown at one heading (a dog-leg to the start of the line, a turn at the
    surface) measures a weighted mean of the correction along it: to first order in ``delta``, each
    dead-reckoned step ``dp_j`` turns the course by ``delta(h_j)`` times its projection on the
    dead-reckoned course ``D``, ``w_j = dp_j . D / |D|^2`` (the ``w_j`` sum to one). Given those
    headings and weights, ``s_i = sum_j w_j s(h_j)``.

    Parameters
    ----------
    model : DeviationModel
        The fitted correction (its constant is replaced).
    compass_heading_rad : array_like, shape (T,), radians; or a sequence of T arrays
        Mean compass heading of each transit; with ``heading_weights``, the compass headings along
        each transit.
    cmg_minus_dr_course_rad : array_like, shape (T,), radians
        GPS course made good minus dead-reckoned course, per transit.
    weights : array_like, shape (T,), optional
        Relative weights of the transits (e.g. inverse course variances); default equal.
    heading_weights : sequence of T arrays, optional
        Weight of each heading along its transit (normalised per transit), e.g. the projections
        ``w_j`` above.
    common_sigma_rad : float
        1-sigma of an error shared by every transit, radians: the yaw misalignment between the
        DVL and the compass turns every dead-reckoned course alike, so the transits cannot tell it
        from ``a0``; the transits' scatter does not show it either. Added to ``a0``'s variance.

    Returns
    -------
    DeviationModel
        Same harmonics, new ``a0``, ``constant_source="gps-transits"``. Its covariance holds the
        shape's covariance and, for ``a0``, the weighted scatter of the transits about the fit
        (variance of a weighted mean, unknown variance factor) plus the shape's propagated
        uncertainty and ``common_sigma_rad`` squared; the shape block is taken as exact when
        ``model`` has no covariance.

    Raises
    ------
    InsufficientDataError
        Fewer than two transits (one fixes the constant but not its uncertainty).
    """
    phi = _transit_rows(compass_heading_rad, heading_weights, model.harmonics)
    y = np.asarray(cmg_minus_dr_course_rad, dtype=float).reshape(-1)
    w = np.ones_like(y) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if not len(phi) == y.size == w.size:
        raise ValueError(f"transit arrays must match; found {len(phi)}, {y.size} and {w.size}")
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(w))):
        raise ValueError("transit course differences and weights must be finite")
    if np.any(w <= 0):
        raise ValueError("transit weights must be positive")
    if not (math.isfinite(common_sigma_rad) and common_sigma_rad >= 0.0):
        raise ValueError(f"common_sigma_rad must be finite and non-negative; found {common_sigma_rad}")
    if y.size < 2:
        raise InsufficientDataError(f"fixing the compass constant needs at least 2 transits; got {y.size}")
    shape = phi @ model.coefficients_rad[1:]
    d = wrap_angle(y - shape)
    wn = w / w.sum()
    a0 = float(wn @ d)
    r = wrap_angle(d - a0)
    var_data = float(wn @ r**2) / (y.size - 1)  # variance of a weighted mean
    g = wn @ phi  # d a0 / d shape = -g
    p = 2 * model.harmonics + 1
    C_shape = np.zeros((p - 1, p - 1)) if model.covariance is None else model.covariance[1:, 1:]
    if model.covariance is None:
        log.warning("fix_constant: the model has no covariance; its shape is taken as exact")
    cov = np.zeros((p, p))
    cov[1:, 1:] = C_shape
    cov[0, 0] = var_data + g @ C_shape @ g + common_sigma_rad**2
    cov[0, 1:] = cov[1:, 0] = -C_shape @ g
    log.info(
        "compass constant from %d transits: %.3f +- %.3f deg (transit residual RMS %.3f deg)",
        y.size,
        math.degrees(a0),
        math.degrees(math.sqrt(cov[0, 0])),
        math.degrees(math.sqrt(float(np.mean(r**2)))),
    )
    return DeviationModel(a0, model.a_rad, model.b_rad, cov, "gps-transits")
