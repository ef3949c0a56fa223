"""Procedural, seeded bathymetry as a function of world coordinates (no arrays the size of the site).

``depth(n, e) = mean + regional slope + undulations - reef structures + rugosity``, metres below the
datum, positive down:

- a regional plane slope (default 0.5%, a random direction);
- undulations: a sum of sinusoids of 40 to 300 m wavelength (default 1.5 m amplitude in all);
- reef structures: on a lattice of 8 m cells, each cell holds with probability 0.7 one
  elliptical mound of 0.5 to 2 m height, 3 to 10 m long and half to fully as wide, at a random
  place and orientation, shaped ``h (1 - r^2)^2`` inside its ellipse (smooth, compact). A cell's
  mound is drawn from a hash of the cell's indices and the seed, so any point needs only its own
  and its eight neighbouring cells;
- rugosity: a sum of sinusoids of 0.3 to 3 m wavelength (default 3 cm amplitude in all).

A seafloor change between repeat surveys of a site (same seed): ``removed_cells`` lists lattice
cells whose mound is gone (a coral head removed); :func:`tallest_mound` finds one worth removing.

The scales follow the mesophotic reef of the paper's field site (section IV and Fig. 10: coral
structures of O(1) m on a lagoon floor 20 to 110 m deep). :meth:`Seafloor.depth_m` and
:meth:`Seafloor.gradient` are vectorised over any shape of coordinates, for ray casting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from auvnav.frames import FloatArray

_NEIGHBOURS_I = np.repeat(np.arange(-1, 2), 3)
_NEIGHBOURS_J = np.tile(np.arange(-1, 2), 3)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1, _MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_ODD = np.uint64(0x632BE59BD9B4E019)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_BITS21 = np.uint64(0x1FFFFF)
_CHUNK = 16384  # points per block in vectorised evaluation (keeps the temporaries in cache)
_CACHE_CELLS = 4096  # neighbourhoods kept for single-point evaluation


@dataclass(frozen=True)
class SeafloorParams:
    """Shape of the procedural seafloor (metres, dimensionless slope)."""

    mean_depth_m: float = 45.0
    slope: float = 0.005
    undulation_m: float = 1.5
    undulation_wavelengths_m: tuple[float, float] = (40.0, 300.0)
    undulation_terms: int = 8
    reef_cell_m: float = 8.0
    reef_probability: float = 0.7
    reef_height_m: tuple[float, float] = (0.5, 2.0)
    reef_length_m: tuple[float, float] = (3.0, 10.0)
    rugosity_m: float = 0.03
    rugosity_wavelengths_m: tuple[float, float] = (0.3, 3.0)
    rugosity_terms: int = 12
    removed_cells: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if self.reef_length_m[1] / 2 > self.reef_cell_m:
            raise ValueError("a reef mound's half-length must not exceed the cell size")
        if not 0 <= self.reef_probability <= 1:
            raise ValueError(f"reef_probability must lie in [0, 1]; found {self.reef_probability}")


def _splitmix64(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """SplitMix64 finaliser (Steele, Lea and Flood, OOPSLA 2014): a well-mixed 64-bit hash."""
    z = x + _GOLDEN  # uint64 arithmetic wraps modulo 2^64
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


def _uniforms(i: NDArray[np.int64], j: NDArray[np.int64], salt: np.uint64) -> list[FloatArray]:
    """Nine independent uniforms in [0, 1) (21 bits each) per lattice cell (i, j), from a hash."""
    key = _splitmix64(_splitmix64(i.astype(np.uint64) ^ salt) ^ (j.astype(np.uint64) * _ODD))
    out = []
    for k in range(3):
        word = _splitmix64(key + np.uint64(k + 1))
        for shift in (43, 22, 1):
            out.append(((word >> np.uint64(shift)) & _BITS21).astype(np.float64) / float(1 << 21))
    return out


@dataclass(frozen=True)
class _Mounds:
    """The reef mounds of cells, arrays over the cells: height, half-axes, orientation, centre."""

    height_m: FloatArray
    a_m: FloatArray
    b_m: FloatArray
    cos: FloatArray
    sin: FloatArray
    north_m: FloatArray
    east_m: FloatArray


def _waves(
    rng: np.random.Generator, n: int, wavelengths_m: tuple[float, float], total_m: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Random plane waves: wavenumbers (north, east), phases, amplitudes (sum of squares = total^2 * 2)."""
    lam = np.exp(rng.uniform(np.log(wavelengths_m[0]), np.log(wavelengths_m[1]), n))
    direction = rng.uniform(0, 2 * np.pi, n)
    k = 2 * np.pi / lam
    phase = rng.uniform(0, 2 * np.pi, n)
    weight = rng.uniform(0.5, 1.0, n) * lam / lam.max()  # longer waves carry more of the relief
    amplitude = total_m * np.sqrt(2.0) * weight / np.sqrt(np.sum(weight**2))
    return k * np.cos(direction), k * np.sin(direction), phase, amplitude


class Seafloor:
    """Seeded procedural bathymetry.

    Parameters
    ----------
    seed : int
        Everything about the seafloor follows from it.
    params : SeafloorParams
    """

    def __init__(self, seed: int, params: SeafloorParams | None = None) -> None:
        self.seed = int(seed)
        self.params = params or SeafloorParams()
        p = self.params
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0x5EAF]))
        slope_direction = rng.uniform(0, 2 * np.pi)
        self._slope_ne = (p.slope * math.cos(slope_direction), p.slope * math.sin(slope_direction))
        self._undulation = _waves(rng, p.undulation_terms, p.undulation_wavelengths_m, p.undulation_m)
        self._rugosity = _waves(rng, p.rugosity_terms, p.rugosity_wavelengths_m, p.rugosity_m)
        self._salt = np.uint64(rng.integers(0, 2**63))
        self._cache: dict[tuple[int, int], _Mounds] = {}

    @staticmethod
    def _waves(
        waves: tuple[FloatArray, ...], n: FloatArray, e: FloatArray, gradient: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """A sum of plane waves and (when ``gradient``, else zeros) its gradient."""
        kn, ke, phase, amp = waves
        arg = n[..., None] * kn + e[..., None] * ke + phase
        height = (amp * np.sin(arg)).sum(-1)
        if not gradient:
            return height, np.zeros_like(height), np.zeros_like(height)
        c = amp * np.cos(arg)
        return height, (kn * c).sum(-1), (ke * c).sum(-1)

    def _mounds(self, i: NDArray[np.int64], j: NDArray[np.int64]) -> _Mounds:
        """The mound of each lattice cell (i, j): drawn from the hash of the cell and the seed."""
        p = self.params
        present, u_n, u_e, u_h, u_len, u_ratio, u_dir, _, _ = _uniforms(i, j, self._salt)
        for ri, rj in p.removed_cells:
            present = np.where((i == ri) & (j == rj), 2.0, present)  # never below the probability
        h_lo, h_hi = p.reef_height_m
        a = 0.5 * (p.reef_length_m[0] + u_len * (p.reef_length_m[1] - p.reef_length_m[0]))
        return _Mounds(
            height_m=np.where(present < p.reef_probability, h_lo + u_h * (h_hi - h_lo), 0.0),
            a_m=a,
            b_m=a * (0.5 + 0.5 * u_ratio),
            cos=np.cos(np.pi * u_dir),
            sin=np.sin(np.pi * u_dir),
            north_m=(i + u_n) * p.reef_cell_m,
            east_m=(j + u_e) * p.reef_cell_m,
        )

    def _neighbourhood(self, i0: int, j0: int) -> _Mounds:
        """The mounds of cell (i0, j0) and its eight neighbours, cached for single points."""
        key = (i0, j0)
        mounds = self._cache.get(key)
        if mounds is None:
            if len(self._cache) >= _CACHE_CELLS:
                self._cache.clear()
            mounds = self._mounds(i0 + _NEIGHBOURS_I, j0 + _NEIGHBOURS_J)
            self._cache[key] = mounds
        return mounds

    @staticmethod
    def _reefs(
        m: _Mounds, n: FloatArray, e: FloatArray, gradient: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Height of mounds ``m`` (last axis) above the floor at (n, e) (shape (..., 1)), and (when
        ``gradient``, else zeros) its gradient."""
        dn, de = n - m.north_m, e - m.east_m
        x = (m.cos * dn + m.sin * de) / m.a_m
        y = (-m.sin * dn + m.cos * de) / m.b_m
        q = np.maximum(1.0 - (x * x + y * y), 0.0)
        height = (m.height_m * q * q).sum(-1)
        if not gradient:
            return height, np.zeros_like(height), np.zeros_like(height)
        # h (1 - r2)^2 with r2 = x^2 + y^2; d/dr2 = -2 h (1 - r2)
        g = -4.0 * m.height_m * q
        grad_n = g * (x * m.cos / m.a_m - y * m.sin / m.b_m)
        grad_e = g * (x * m.sin / m.a_m + y * m.cos / m.b_m)
        return height, grad_n.sum(-1), grad_e.sum(-1)

    def _floor(
        self, n: FloatArray, e: FloatArray, reefs: tuple[FloatArray, FloatArray, FloatArray], gradient: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        und, und_n, und_e = self._waves(self._undulation, n, e, gradient)
        rug, rug_n, rug_e = self._waves(self._rugosity, n, e, gradient)
        reef, reef_n, reef_e = reefs
        sn, se = self._slope_ne
        depth = self.params.mean_depth_m + sn * n + se * e + und + rug - reef
        return depth, sn + und_n + rug_n - reef_n, se + und_e + rug_e - reef_e

    def _evaluate(
        self, north_m: ArrayLike, east_m: ArrayLike, gradient: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        n, e = np.broadcast_arrays(np.asarray(north_m, dtype=float), np.asarray(east_m, dtype=float))
        shape = n.shape
        n, e = n.ravel(), e.ravel()
        out = np.empty((3, n.size))
        cell = self.params.reef_cell_m
        for start in range(0, n.size, _CHUNK):
            bn, be = n[start : start + _CHUNK, None], e[start : start + _CHUNK, None]
            i = np.floor(bn / cell).astype(np.int64) + _NEIGHBOURS_I
            j = np.floor(be / cell).astype(np.int64) + _NEIGHBOURS_J
            reefs = self._reefs(self._mounds(i, j), bn, be, gradient)
            out[:, start : start + _CHUNK] = self._floor(bn[:, 0], be[:, 0], reefs, gradient)
        return out[0].reshape(shape), out[1].reshape(shape), out[2].reshape(shape)

    def depth_m(self, north_m: ArrayLike, east_m: ArrayLike) -> FloatArray:
        """Seafloor depth below the datum, metres, positive down, at local NED (north, east).

        Parameters
        ----------
        north_m, east_m : array_like, broadcasting, metres, local NED

        Returns
        -------
        ndarray, the broadcast shape, metres
        """
        return self._evaluate(north_m, east_m, gradient=False)[0]

    def gradient(self, north_m: ArrayLike, east_m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(d depth / d north, d depth / d east)``, dimensionless, at (north, east)."""
        _, gn, ge = self._evaluate(north_m, east_m, gradient=True)
        return gn, ge

    def depth_and_gradient(self, north_m: float, east_m: float) -> tuple[float, float, float]:
        """Depth and gradient at one point, as floats (the vehicle's altitude loop; cached mounds)."""
        cell = self.params.reef_cell_m
        mounds = self._neighbourhood(math.floor(north_m / cell), math.floor(east_m / cell))
        n, e = np.array([north_m]), np.array([east_m])
        d, gn, ge = self._floor(n, e, self._reefs(mounds, n[:, None], e[:, None], True), True)
        return float(d[0]), float(gn[0]), float(ge[0])


@dataclass(frozen=True)
class Mound:
    """One reef mound: its lattice cell, centre (local NED, metres), height and half-axes (metres)."""

    cell: tuple[int, int]
    north_m: float
    east_m: float
    height_m: float
    a_m: float
    b_m: float

    @property
    def area_m2(self) -> float:
        """Area of its footprint ellipse, m^2."""
        return math.pi * self.a_m * self.b_m


def tallest_mound(
    seafloor: Seafloor,
    north_m: tuple[float, float],
    east_m: tuple[float, float],
    *,
    points_ne_m: FloatArray | None = None,
    min_density: float = 0.0,
) -> Mound:
    """The tallest mound whose centre lies inside the box ``north_m x east_m`` (metres) and, when
    ``points_ne_m`` (N, 2) are given, with at least ``min_density`` of them per m^2 inside its ellipse's
    inscribed circle (a mound the images cover)."""
    cell = seafloor.params.reef_cell_m
    i, j = np.meshgrid(
        np.arange(math.floor(north_m[0] / cell) - 1, math.floor(north_m[1] / cell) + 2),
        np.arange(math.floor(east_m[0] / cell) - 1, math.floor(east_m[1] / cell) + 2),
        indexing="ij",
    )
    m = seafloor._mounds(i.ravel(), j.ravel())
    inside = (
        (m.height_m > 0)
        & (m.north_m >= north_m[0])
        & (m.north_m <= north_m[1])
        & (m.east_m >= east_m[0])
        & (m.east_m <= east_m[1])
    )
    if points_ne_m is not None and np.any(inside):
        from scipy.spatial import cKDTree

        tree = cKDTree(np.asarray(points_ne_m, dtype=float))
        centres = np.column_stack([m.north_m, m.east_m])
        counts = np.array([len(tree.query_ball_point(c, r)) for c, r in zip(centres, m.b_m, strict=True)])
        inside &= counts >= min_density * np.pi * m.b_m**2
    if not np.any(inside):
        raise ValueError(f"no reef mound lies inside north {north_m} x east {east_m} m")
    k = int(np.argmax(np.where(inside, m.height_m, -1.0)))
    return Mound(
        (int(i.ravel()[k]), int(j.ravel()[k])),
        float(m.north_m[k]),
        float(m.east_m[k]),
        float(m.height_m[k]),
        float(m.a_m[k]),
        float(m.b_m[k]),
    )
