"""Procedural benthic albedo: a seeded function of world position (north, east), never a stored image.

Because the albedo is a function of the world point, the same patch of seafloor looks the same from any
pose (up to lighting and sampling), which is what makes visual loop closures possible, and nothing of
the size of a survey site is ever held in memory.

The scene mixes the habitats of a shallow tropical reef slope such as Scott Reef (the paper's section V):

- sand with wave ripples (wavelength ~9 cm, crests bending with a low-frequency field) and grain texture;
- rubble: pebbles and shell fragments, bright and dark blobs of 1-4 cm, in patches;
- coral-like patches of 1-3 m with irregular edges, high-contrast ridged structure at 2-8 cm and polyps;
- featureless sand (``bare_fraction``): patches of 0.5-2 m where the sand shows no detail at survey
  altitude, and fields of regular ripples (``ripple_field_fraction``): straight crests of one
  wavelength over metres, alike from patch to patch, the repetitive texture that invites false loops.

What is matched to real seafloor photographs (issue 20): the contrast, and the spectrum's slope. A
colour-corrected AUV photograph of a sandy reef seafloor has a grey-level standard deviation of about 8
(8-bit); the default ``contrast`` 0.6 gives rendered images whose robust standard deviation after
illumination correction (:func:`auvnav.vision.features.robust_contrast`) is 16 in clear water, 13 in
coastal and 7 in turbid water (medians over 12 half-scale views of the check dive; 9-24, 7-19 and 3-11).
Natural images have power spectra falling about as ``1/f^2`` (Field 1987, "Relations between the
statistics of natural images and the response properties of cortical cells", JOSA A 4(12); van der
Schaaf and van Hateren 1996, Vision Research 36(17): exponent -1.88 +/- 0.43); the grain and rubble are
fBm with equal amplitude per octave, which is that spectrum. Measured on the same rendered views
(radial power spectrum, 4-60 cycles per image): exponent -2.5 median (-1.3 to -3.8), steeper than the
photographs' because the featureless sand and the smooth ripple fields have little fine detail.

Each ingredient is value noise: seeded random values on a square lattice of spacing ``L`` metres,
hashed from the integer lattice coordinates (so any window of the world evaluates identically), and
interpolated bicubically with ``cv2.remap``. Octaves finer than the pixel footprint are faded out
(anti-aliasing, the pixel integrating the finest detail as a real sensor does).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.vision.camera import remap_rows

FloatArray = NDArray[np.float64]

_TILE_M = 8.0  # points are evaluated in world tiles of this size, so lattice windows stay small
_MARGIN = 3  # lattice cells around a window: the bicubic kernel reads 2 beyond each side


def _hash_unit(i: NDArray[np.int64], j: NDArray[np.int64], salt: int) -> NDArray[np.float32]:
    """Deterministic values in [-1, 1) from integer lattice coordinates (murmur3's 64-bit finaliser)."""
    h = i.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    h ^= j.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
    h ^= np.uint64(salt & 0xFFFFFFFFFFFFFFFF)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xFF51AFD7ED558CCD)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xC4CEB9FE1A85EC53)
    h ^= h >> np.uint64(33)
    return ((h >> np.uint64(40)).astype(np.float32) * np.float32(2.0**-23) - np.float32(1.0)).astype(
        np.float32
    )


def _cubic_weights(x: FloatArray, a: float = -0.75) -> list[FloatArray]:
    """OpenCV's bicubic interpolation weights (``interpolateCubic``, A = -0.75) for offsets x in [0, 1)."""
    w0 = ((a * (x + 1) - 5 * a) * (x + 1) + 8 * a) * (x + 1) - 4 * a
    w1 = ((a + 2) * x - (a + 3)) * x * x + 1
    w2 = ((a + 2) * (1 - x) - (a + 3)) * (1 - x) * (1 - x) + 1
    return [w0, w1, w2, 1 - w0 - w1 - w2]


def _smoothstep(lo: float, hi: float, x: NDArray[np.float32]) -> NDArray[np.float32]:
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


class _Window:
    """Points of one world tile, laid out as a 2-D map for ``cv2.remap`` (2-D input keeps its layout)."""

    def __init__(self, north_m: FloatArray, east_m: FloatArray) -> None:
        n = north_m.size
        self.n = n
        self.shape = north_m.shape
        if north_m.ndim == 2:
            self.north, self.east = north_m, east_m
        else:
            self.north, self.east = remap_rows(north_m, east_m)
        self.lo = (float(north_m.min()), float(east_m.min()))
        self.hi = (float(north_m.max()), float(east_m.max()))
        # float32 offsets from the window's corner: exact to a micrometre over a tile, fast to scale.
        self.north_rel = (self.north - self.lo[0]).astype(np.float32)
        self.east_rel = (self.east - self.lo[1]).astype(np.float32)

    def noise(self, spacing_m: float, salt: int) -> NDArray[np.float32]:
        """Value noise of lattice spacing ``spacing_m`` at the window's points, in about [-1, 1]."""
        i0 = int(np.floor(self.lo[0] / spacing_m)) - _MARGIN
        j0 = int(np.floor(self.lo[1] / spacing_m)) - _MARGIN
        i1 = int(np.floor(self.hi[0] / spacing_m)) + _MARGIN
        j1 = int(np.floor(self.hi[1] / spacing_m)) + _MARGIN
        if (i1 - i0 + 1) * (j1 - j0 + 1) > 16 * self.north.size:
            return self._sparse_noise(spacing_m, salt)
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1), indexing="ij")
        lattice = _hash_unit(ii, jj, salt)
        # lattice rows = north, columns = east; remap's x is the column coordinate.
        scale = np.float32(1.0 / spacing_m)
        map_x = self.east_rel * scale + np.float32(self.lo[1] / spacing_m - j0)
        map_y = self.north_rel * scale + np.float32(self.lo[0] / spacing_m - i0)
        return cv2.remap(lattice, map_x, map_y, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)

    def _sparse_noise(self, spacing_m: float, salt: int) -> NDArray[np.float32]:
        """The same noise for points scattered over a window much larger than they fill: each point's
        4 x 4 lattice neighbourhood is hashed directly and weighted with OpenCV's bicubic kernel."""
        u = self.north / spacing_m
        v = self.east / spacing_m
        iu, iv = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        wu, wv = _cubic_weights(u - iu), _cubic_weights(v - iv)
        out = np.zeros(self.north.shape, dtype=np.float64)
        for a in range(4):
            for b in range(4):
                out += wu[a] * wv[b] * _hash_unit(iu + (a - 1), iv + (b - 1), salt)
        return out.astype(np.float32)

    def flat(self, values: NDArray[np.float32]) -> NDArray[np.float32]:
        """Values in the layout of the points given."""
        if len(self.shape) == 2:
            return values
        return values.ravel()[: self.n]


#: Colour of each habitat: reflectance in the camera's red, green and blue bands relative to the grey
#: (luminance, ITU-R BT.601 weights) albedo. Sand: the coral sand of Maritorena, Morel and Gentili (1994),
#: "Diffuse reflectance of oceanic shallow waters: influence of water depth and bottom albedo", Limnol.
#: Oceanogr. 39(7), Fig. 6 (0.37 at 475 nm, 0.42 at 525 nm, rising slowly into the red: 0.47 taken for
#: 600-650 nm). Coral and algae: dark in the blue and green where their pigments absorb, brighter in the
#: red (their brown algae: 0.028 at 475 nm, 0.041 at 525 nm; 0.09 taken for the red).
SAND_RGB = (0.47, 0.42, 0.37)
CORAL_RGB = (0.09, 0.05, 0.03)
LUMA_RGB = (0.299, 0.587, 0.114)


def _tint(rgb: tuple[float, float, float]) -> NDArray[np.float32]:
    """A colour as multipliers of its luminance."""
    luma = sum(w * c for w, c in zip(LUMA_RGB, rgb, strict=True))
    return np.array(rgb, dtype=np.float32) / np.float32(luma)


@dataclass(frozen=True)
class SeafloorTexture:
    """Seeded benthic albedo field, grey (:meth:`albedo`) or in the camera's three bands (:meth:`albedo_rgb`).

    Parameters
    ----------
    seed : int
        Selects the scene; the same seed gives the same seafloor everywhere.
    coral_fraction : float
        Approximate fraction of the area covered by coral-like patches, 0..1.
    ripple_wavelength_m : float
        Sand ripple wavelength, metres (wave ripples on reef sand: 5-15 cm).
    bare_fraction : float
        Approximate fraction of the sand that is featureless: fine sand with neither grain texture
        visible at survey altitude, nor rubble, nor ripples (patches of 0.5-2 m).
    ripple_field_fraction : float
        Approximate fraction of the sand covered by fields of regular ripples: straight crests of one
        wavelength and direction over metres, the same from one patch to the next (repetitive texture
        that invites false loop closures).
    contrast : float
        Scales every variation of the albedo about its habitat's mean (1: the structure as designed;
        the default matches the contrast of real seafloor photographs, see the module docstring).
    """

    seed: int = 0
    coral_fraction: float = 0.35
    ripple_wavelength_m: float = 0.09
    bare_fraction: float = 0.2
    ripple_field_fraction: float = 0.25
    contrast: float = 0.6

    def __post_init__(self) -> None:
        for name in ("coral_fraction", "bare_fraction", "ripple_field_fraction"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1]; found {value}")
        if self.ripple_wavelength_m <= 0:
            raise ValueError(f"ripple_wavelength_m must be positive; found {self.ripple_wavelength_m}")
        if not 0.0 < self.contrast <= 2.0:
            raise ValueError(f"contrast must be in (0, 2]; found {self.contrast}")

    def albedo(self, north_m: FloatArray, east_m: FloatArray, *, footprint_m: float = 0.0) -> FloatArray:
        """Diffuse reflectance at world points, grey: the luminance of :meth:`albedo_rgb`.

        Parameters
        ----------
        north_m, east_m : ndarray, same shape
            Points on the seafloor, metres, local NED.
        footprint_m : float
            Size of one pixel on the seafloor, metres; detail finer than about two pixels is faded out.
            0 keeps every octave.

        Returns
        -------
        ndarray, same shape, float32 reflectance in [0.02, 0.95].
        """
        return self._evaluate(north_m, east_m, footprint_m, rgb=False)

    def albedo_rgb(
        self, north_m: FloatArray, east_m: FloatArray, *, footprint_m: float = 0.0
    ) -> NDArray[np.float32]:
        """Diffuse reflectance in the camera's red, green and blue bands at world points.

        Returns
        -------
        ndarray, shape (..., 3), float32 reflectance in [0.01, 0.95], channels (red, green, blue).
        """
        return self._evaluate(north_m, east_m, footprint_m, rgb=True)

    def _evaluate(self, north_m: FloatArray, east_m: FloatArray, footprint_m: float, rgb: bool) -> NDArray:
        north_m = np.asarray(north_m, dtype=float)
        east_m = np.asarray(east_m, dtype=float)
        if north_m.shape != east_m.shape:
            raise ValueError(f"north_m and east_m must match; found {north_m.shape} and {east_m.shape}")
        bands = (3,) if rgb else ()
        flat_n, flat_e = north_m.ravel(), east_m.ravel()
        out = np.empty((flat_n.size, *bands), dtype=np.float32)
        if flat_n.size == 0:
            return out.reshape(*north_m.shape, *bands)
        if (
            north_m.ndim == 2
            and north_m.shape[1] < 32767
            and np.ptp(flat_n) < _TILE_M
            and np.ptp(flat_e) < _TILE_M
        ):
            # an image's worth of points: one window, in the points' own layout
            return self._albedo_window(_Window(north_m, east_m), footprint_m, rgb)
        tile = np.floor(flat_n / _TILE_M).astype(np.int64) * 1_000_003 + np.floor(flat_e / _TILE_M).astype(
            np.int64
        )
        order = np.argsort(tile, kind="stable")
        bounds = np.flatnonzero(np.diff(tile[order])) + 1
        for idx in np.split(order, bounds):
            out[idx] = self._albedo_window(_Window(flat_n[idx], flat_e[idx]), footprint_m, rgb)
        return out.reshape(*north_m.shape, *bands)

    def habitat(self, north_m: FloatArray, east_m: FloatArray) -> NDArray[np.str_]:
        """The habitat at world points: ``"reef"`` (coral), ``"ripple"`` (a field of regular ripples),
        ``"bare"`` (featureless sand) or ``"sand"`` (sand with grain, rubble and wave ripples), each
        where its share of the blend is over a half (benchmarks score loop closures by habitat)."""
        north_m = np.atleast_1d(np.asarray(north_m, dtype=float))
        east_m = np.atleast_1d(np.asarray(east_m, dtype=float))
        w = _Window(north_m.ravel(), east_m.ravel())
        coral, bare, field = (w.flat(x) for x in self._habitats(w, self._octave(w, 0.0)))
        out = np.full(w.n, "sand", dtype="<U6")
        out[bare > 0.5] = "bare"
        out[field > 0.5] = "ripple"
        out[coral > 0.5] = "reef"
        return out.reshape(north_m.shape)

    def _octave(self, w: _Window, footprint_m: float) -> Callable[[float, int], NDArray[np.float32]]:
        """Value noise of a given lattice spacing and salt at the window's points, faded out where
        finer than the pixel footprint (``footprint_m``; 0 keeps every octave)."""
        salt = self.seed * 0x2545F4914F6CDD1D

        def octave(spacing_m: float, k: int) -> NDArray[np.float32]:
            fade = (
                1.0 if footprint_m <= 0 else float(_smoothstep(1.0, 2.5, np.float32(spacing_m / footprint_m)))
            )
            if fade == 0.0:
                return np.zeros_like(w.north, dtype=np.float32)
            return fade * w.noise(spacing_m, salt + 7919 * k)

        return octave

    def _habitats(
        self, w: _Window, octave: Callable[[float, int], NDArray[np.float32]]
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """The shares of coral, featureless sand and ripple field at the window's points, 0..1."""

        def level(fraction: float) -> float:
            """The value-noise level exceeded over about ``fraction`` of the area."""
            return 0.6 - 1.2 * fraction

        # Habitat: coral patches where a low-frequency field exceeds a level set by the cover fraction.
        habitat = 0.65 * octave(3.0, 1) + 0.35 * octave(1.2, 2) + 0.18 * octave(0.35, 3)
        lc = level(self.coral_fraction)
        coral = _smoothstep(lc, lc + 0.08, habitat)
        # Featureless sand: patches where the sand's detail fades out.
        lb = level(self.bare_fraction)
        bare = _smoothstep(lb, lb + 0.12, 0.8 * octave(1.5, 20) + 0.2 * octave(0.5, 21))
        # Ripple fields: where a field of scale 5 m exceeds its level, off the coral.
        lr = level(self.ripple_field_fraction)
        field = _smoothstep(lr, lr + 0.1, octave(5.0, 22)) * (1.0 - coral)
        return coral, bare, field

    def _albedo_window(self, w: _Window, footprint_m: float, rgb: bool) -> NDArray[np.float32]:
        octave = self._octave(w, footprint_m)
        coral, bare, field = self._habitats(w, octave)
        detail = 1.0 - 0.9 * bare

        # Sand: grain texture (fBm: equal amplitude per octave, a power spectrum falling as 1/f^2) plus
        # wave ripples whose crests bend and fade.
        grain = 0.06 * octave(0.25, 4) + 0.05 * octave(0.08, 5) + 0.06 * octave(0.02, 6)
        grain += 0.07 * octave(0.008, 7) + 0.06 * octave(0.004, 8)
        theta = 0.8 * np.pi * octave(6.0, 9) + self.seed
        phase = (np.cos(theta) * w.north + np.sin(theta) * w.east) * (2 * np.pi / self.ripple_wavelength_m)
        ripples = np.sin(phase + 4.0 * octave(0.6, 10)).astype(np.float32)
        ripple_amp = 0.10 * _smoothstep(-0.3, 0.3, octave(2.0, 11))
        sand = grain + ripple_amp * ripples

        # Rubble: bright and dark fragments in patches, at two sizes.
        rubble = _smoothstep(-0.1, 0.4, octave(1.5, 12))
        bright = _smoothstep(0.35, 0.6, octave(0.025, 13)) + 0.7 * _smoothstep(0.45, 0.7, octave(0.012, 14))
        dark = _smoothstep(0.4, 0.65, octave(0.03, 15))
        sand += rubble * (0.30 * bright - 0.30 * dark)
        sand *= detail

        # Ripple fields: straight crests, one wavelength, a direction that turns only over tens of metres.
        heading = 0.3 * np.pi * octave(40.0, 23) + 0.5 * self.seed
        crest = (np.cos(heading) * w.north + np.sin(heading) * w.east) * (
            2 * np.pi / self.ripple_wavelength_m
        )
        crest = crest + 0.4 * octave(1.0, 24)
        regular = (np.sin(crest) + 0.25 * np.sin(2 * crest + 0.8)).astype(np.float32)
        sand = (1.0 - field) * sand + field * (0.12 * regular + 0.02 * octave(0.02, 25))
        sand = 0.50 + self.contrast * sand

        # Coral: ridged structure (1 - |noise|) at two scales, with small polyps.
        ridge1 = 1.0 - np.abs(octave(0.07, 16))
        ridge2 = 1.0 - np.abs(octave(0.028, 17))
        polyps = _smoothstep(0.3, 0.7, octave(0.007, 18))
        reef = 0.18 + 0.40 * ridge1**3 + 0.20 * ridge2**2 + 0.12 * polyps + 0.05 * octave(0.4, 19)
        reef = REEF_MEAN + self.contrast * (reef - REEF_MEAN)

        albedo = (1.0 - coral) * sand + coral * reef
        if not rgb:
            return np.clip(w.flat(albedo), 0.02, 0.95)
        # Colour: each habitat's, varying a little from place to place.
        tint = (1.0 - coral)[..., None] * _tint(SAND_RGB) + coral[..., None] * _tint(CORAL_RGB)
        hue = 0.06 * octave(0.8, 26)
        tint = tint * (1.0 + np.stack([hue, np.zeros_like(hue), -hue], axis=-1))
        tint /= (tint @ np.array(LUMA_RGB, dtype=np.float32))[..., None]  # keep the luminance
        out = np.clip(albedo[..., None] * tint, 0.01, 0.95)
        if len(w.shape) == 2:
            return out
        return out.reshape(-1, 3)[: w.n]


REEF_MEAN = 0.33  # mean albedo of the coral structure above
