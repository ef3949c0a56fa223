"""Stereo rendering of the procedural seafloor: calibrated down-looking pairs by ray casting.

Each pixel's ray (through the lens distortion of the calibration) is intersected with the seafloor
heightfield ``depth_m(north, east)``: fixed-point and secant iterations on a coarse grid of pixels, the
ray length interpolated bicubically to every pixel (the seafloor is smooth at the scale of
centimetres). The hit point's albedo, in the camera's red, green and blue bands, comes from
:class:`~auvnav.sim.texture.SeafloorTexture` in world coordinates. Image formation follows the
Jaffe-McGlamery model in each band (:func:`render_view`), in the water of ``auvnav simulate --water
clear|coastal|turbid`` (:func:`water_type`: Jerlov's attenuation per band, split into absorption and
scattering with Petzold's measured waters): the strobes' light (inverse-square falloff, beam pattern,
Lambert's cosine) attenuated on its way down and back, the unscattered (sharp) and forward-scattered
(blurred) parts of the returning light, the backscatter of the water column lit by the strobes, ``cos^4``
vignetting, motion blur over the flash at the vehicle's velocity, then the sensor: gain set for the
water, shot and read noise, 8-bit quantisation, an RGGB Bayer mosaic demosaiced to BGR images.

Default rig (:func:`default_stereo_rig`): ACFR's Sirius AUV, the paper's vehicle. Johnson-Roberson,
Pizarro, Williams and Mahon (2010), "Generation and visualization of large-scale three-dimensional
reconstructions from underwater robotic surveys", J. Field Robotics 27(1): 21-51, section 3: a pair of
1360 x 1024 Prosilica cameras (Sony ICX285 CCD) with about 42 x 34 degrees field of view, a baseline of
about 7 cm, looking down from 2 m altitude, images at 1 Hz with strobes.

Camera frame: x right, y down in the image, z along the optical axis. Mount: the optical axis is body
down, image x is body right (starboard), so the top of the image faces forward:
``R_body_cam = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]`` (a 90 degree yaw). The right camera sits 7 cm to
starboard of the left one.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.dive import ImageIndex
from auvnav.executor import Executor, SerialExecutor, chunks
from auvnav.footprint import SeafloorLike
from auvnav.frames import se3, se3_inverse
from auvnav.sim.texture import LUMA_RGB, SeafloorTexture
from auvnav.streams import write_stream
from auvnav.trajectory import Trajectory
from auvnav.vehicle import CameraModel, Mount, StereoRig
from auvnav.vision.camera import pixel_rays

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

# Johnson-Roberson et al. (2010), J. Field Robotics 27(1), section 3 (Sirius).
SIRIUS_WIDTH_PX = 1360
SIRIUS_HEIGHT_PX = 1024
SIRIUS_HFOV_DEG = 42.0
SIRIUS_BASELINE_M = 0.07
# Sony ICX285 (Prosilica GC1380) full-well capacity, about 18,000 electrons (Sony ICX285AL datasheet);
# read noise of such CCD cameras is ~10-15 electrons (0.2 DN at 8 bits).
FULL_WELL_E = 18000.0
READ_NOISE_E = 14.0
#: Exposure of a strobe-lit image: the flash, not the shutter, sets it; a xenon strobe's flash at full
#: power lasts a few milliseconds (assumed 2 ms). At 0.5 m/s the image moves about 0.9 px at full scale.
FLASH_S = 0.002

# Water (:class:`Water`). Jerlov (1976), "Marine Optics", 2nd ed., Elsevier, Table XXVII (p. 135): the
# downwelling diffuse attenuation coefficient K_d (1/m) that defines each water type, every 25 nm
# (oceanic IB; coastal 3C, 5C, 7C).
JERLOV_WAVELENGTHS_NM = (425, 450, 475, 500, 525, 550, 575, 600, 625, 650)
JERLOV_KD_PER_M = {
    "IB": (0.042, 0.036, 0.033, 0.042, 0.054, 0.072, 0.099, 0.245, 0.315, 0.375),
    "3C": (0.54, 0.39, 0.29, 0.22, 0.20, 0.19, 0.21, 0.33, 0.40, 0.46),
    "5C": (0.78, 0.56, 0.43, 0.36, 0.31, 0.30, 0.33, 0.40, 0.48, 0.54),
    "7C": (1.2, 0.89, 0.71, 0.58, 0.49, 0.46, 0.46, 0.48, 0.54, 0.63),
}
#: The pass bands of the camera's red, green and blue Bayer filters, nm (K_d averaged over each).
CHANNEL_BANDS_NM = ((600, 650), (500, 575), (425, 500))
#: Single-scattering albedo b / c at 530 nm of Petzold's (1972) three measured waters, clear ocean
#: (Bahamas), coastal ocean and turbid harbour (San Diego), as tabulated by Mobley (1994), "Light and
#: Water", Academic Press, Table 3.10.
PETZOLD_SCATTERING_ALBEDO = {"clear": 0.247, "coastal": 0.551, "turbid": 0.833}
#: Backscattering ratio b_b / b of Petzold's average-particle phase function (Mobley 1994, section 3.8).
BACKSCATTER_RATIO = 0.0183
#: Kirk (1984), "Dependence of relationship between inherent and apparent optical properties of water on
#: solar altitude", Limnol. Oceanogr. 29(2): K_d mu0 = sqrt(a^2 + (0.425 mu0 - 0.19) a b); light along
#: the axis, mu0 = 1.
KIRK_G = 0.425 - 0.19
#: The named waters of ``auvnav simulate --water``: a Jerlov type (the attenuation of each channel)
#: and the Petzold water whose single-scattering albedo splits it into absorption and scattering.
WATER_TYPES = {"clear": ("IB", "clear"), "coastal": ("3C", "coastal"), "turbid": ("5C", "turbid")}
#: Forward scattering: the scattered light that still reaches the camera arrives spread about the ray, as
#: two Gaussians of these angular standard deviations (rad) carrying these fractions of it. Ocean
#: particles scatter mostly within a few degrees (Petzold's volume scattering functions, Mobley 1994
#: Fig. 3.13: about half of b within 2-3 degrees); light scattered at angle theta a distance z above the
#: floor appears displaced by theta z / s from a camera at range s, half of theta on average along the
#: path, hence widths of half the scattering angles. The narrow part blurs the detail, the wide one is
#: the veil about bright areas.
FORWARD_SCATTER = ((0.0025, 0.5), (0.025, 0.5))
#: Samples along each ray for the backscatter integral.
BACKSCATTER_SAMPLES = 16

# Rays are cast exactly on a grid of about this many columns; ray lengths are interpolated bicubically
# in between (~3 cm apart on the seafloor at 2 m: the error is well under a millimetre on a smooth floor).
COARSE_GRID_COLUMNS = 48

R_BODY_CAM = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def default_stereo_rig() -> StereoRig:
    """The Sirius-like stereo pair: 1360 x 1024, 42 degrees horizontal FOV, 7 cm baseline, looking down.

    The two cameras are slightly different, as calibrated cameras are (focal lengths within 0.5%,
    principal points a few pixels off centre, mild barrel distortion of a flat port, and a 0.1-0.2 degree
    relative rotation), so that rectification is exercised. The left camera sits 0.4 m forward of the
    body origin, 3.5 cm to port, 0.3 m down.
    """
    fx = (SIRIUS_WIDTH_PX / 2) / np.tan(np.radians(SIRIUS_HFOV_DEG) / 2)
    left = CameraModel(
        SIRIUS_WIDTH_PX,
        SIRIUS_HEIGHT_PX,
        np.array([[fx, 0.0, 683.5], [0.0, fx * 1.001, 508.0], [0.0, 0.0, 1.0]]),
        np.array([-0.06, 0.02, 0.0005, -0.0003, 0.0]),
    )
    right = CameraModel(
        SIRIUS_WIDTH_PX,
        SIRIUS_HEIGHT_PX,
        np.array([[fx * 1.004, 0.0, 677.0], [0.0, fx * 1.005, 514.5], [0.0, 0.0, 1.0]]),
        np.array([-0.055, 0.018, -0.0004, 0.0002, 0.0]),
    )
    R = cv2.Rodrigues(np.radians([0.15, -0.1, 0.2]))[0]
    c_right_in_left = np.array([SIRIUS_BASELINE_M, 0.0005, 0.001])
    t = -R @ c_right_in_left
    mount = Mount(R_BODY_CAM.copy(), np.array([0.4, -SIRIUS_BASELINE_M / 2, 0.3]))
    return StereoRig(left, right, R, t, mount)


def scale_camera_rig(rig: StereoRig, factor: float) -> StereoRig:
    """The same rig for images resized by ``factor`` (intrinsics scaled, extrinsics unchanged)."""
    if factor <= 0:
        raise ValueError(f"scale factor must be positive; found {factor}")
    return StereoRig(
        rig.left.scaled(factor), rig.right.scaled(factor), rig.R_right_left, rig.t_right_left_m, rig.mount
    )


@dataclass(frozen=True)
class Water:
    """Optical properties of the water in the camera's red, green and blue bands (1/m).

    Parameters
    ----------
    name : str
    jerlov_type : str
        The Jerlov water type whose K_d (:data:`JERLOV_KD_PER_M`) gives ``attenuation_per_m``.
    attenuation_per_m : (float, float, float)
        K, the attenuation of the light that forms the image (directly transmitted plus forward
        scattered), red, green, blue: Jerlov's K_d averaged over each band (:data:`CHANNEL_BANDS_NM`).
    absorption_per_m, scattering_per_m : (float, float, float)
        a and b, from K by Kirk's relation (:data:`KIRK_G`) at the single-scattering albedo of the
        Petzold water named in :data:`WATER_TYPES`.
    backscatter_ratio : float
        b_b / b.
    """

    name: str
    jerlov_type: str
    attenuation_per_m: tuple[float, float, float]
    absorption_per_m: tuple[float, float, float]
    scattering_per_m: tuple[float, float, float]
    backscatter_ratio: float = BACKSCATTER_RATIO

    def __post_init__(self) -> None:
        for name in ("attenuation_per_m", "absorption_per_m", "scattering_per_m"):
            value = getattr(self, name)
            if len(value) != 3 or min(value) < 0:
                raise ValueError(f"Water.{name} must be three non-negative numbers; found {value}")
        if any(a + b < k - 1e-9 for k, a, b in zip(*self._abk(), strict=True)):
            raise ValueError("the beam attenuation a + b must not be below the attenuation K")

    def _abk(self) -> tuple[tuple[float, ...], ...]:
        return self.attenuation_per_m, self.absorption_per_m, self.scattering_per_m

    @property
    def K(self) -> NDArray[np.float32]:
        return np.array(self.attenuation_per_m, dtype=np.float32)

    @property
    def c(self) -> NDArray[np.float32]:
        """Beam attenuation a + b, the attenuation of the unscattered (sharp) image."""
        return np.array(self.absorption_per_m, dtype=np.float32) + np.array(
            self.scattering_per_m, dtype=np.float32
        )

    @property
    def bb(self) -> NDArray[np.float32]:
        """Backscattering coefficient b_b."""
        return np.float32(self.backscatter_ratio) * np.array(self.scattering_per_m, dtype=np.float32)

    def describe(self) -> dict[str, Any]:
        """Plain data for ``truth/imaging.yaml``."""
        return {
            "name": self.name,
            "jerlov_type": self.jerlov_type,
            "bands_nm": {"red": list(CHANNEL_BANDS_NM[0]), "green": list(CHANNEL_BANDS_NM[1]),
                         "blue": list(CHANNEL_BANDS_NM[2])},
            "attenuation_per_m": [round(float(x), 5) for x in self.attenuation_per_m],
            "absorption_per_m": [round(float(x), 5) for x in self.absorption_per_m],
            "scattering_per_m": [round(float(x), 5) for x in self.scattering_per_m],
            "backscatter_ratio": self.backscatter_ratio,
        }  # fmt: skip


WaterName = Literal["clear", "coastal", "turbid"]


def water_type(name: WaterName) -> Water:
    """The named water (:data:`WATER_TYPES`): Jerlov's K_d averaged over each colour band, split into
    absorption a and scattering b by Kirk's relation ``K^2 = a^2 + G a b`` at the single-scattering
    albedo ``w = b / (a + b)`` of the matching Petzold water (``b / a = w / (1 - w)``)."""
    if name not in WATER_TYPES:
        raise ValueError(f"water must be one of {', '.join(WATER_TYPES)}; found {name!r}")
    jerlov, petzold = WATER_TYPES[name]
    wl = np.array(JERLOV_WAVELENGTHS_NM)
    kd = np.array(JERLOV_KD_PER_M[jerlov])
    K = tuple(float(kd[(wl >= lo) & (wl <= hi)].mean()) for lo, hi in CHANNEL_BANDS_NM)
    w = PETZOLD_SCATTERING_ALBEDO[petzold]
    ratio = w / (1.0 - w)
    a = tuple(k / np.sqrt(1.0 + KIRK_G * ratio) for k in K)
    b = tuple(x * ratio for x in a)
    return Water(name, jerlov, K, tuple(map(float, a)), tuple(map(float, b)))  # type: ignore[arg-type]


@dataclass(frozen=True)
class Lighting:
    """Strobes, water and sensor.

    Parameters
    ----------
    lamps_body_m : ndarray, shape (k, 3)
        Lamp positions, metres, body FRD (Sirius carries two strobes fore and aft of the cameras).
    aim_body_m : ndarray, shape (3,)
        The point every lamp is aimed at, metres, body FRD (default: 2 m below the cameras).
    beam_exponent : float
        Lamp beam pattern ``cos(angle from the lamp's axis) ** beam_exponent`` (2.5: half the
        intensity 41 degrees off the axis).
    water : Water
        Attenuation, scattering and backscatter (:func:`water_type`).
    exposure : float
        Digital number of the green channel of a 0.5-albedo flat seafloor straight below the camera at
        ``reference_altitude_m`` (the camera's gain is set for the water, up to ``max_gain``).
    reference_altitude_m : float
        Altitude at which ``exposure`` holds (the survey altitude).
    full_well_e, read_noise_e : float
        Electrons for 255 DN at the camera's base gain (in the clear water of :func:`water_type`, the
        strobes give ``exposure`` DN at base gain), and read noise, electrons.
    max_gain : float
        The most the camera's gain is raised over its base to reach ``exposure`` in darker water.
    flash_s : float
        Exposure (the strobe's flash), seconds: motion blur at the vehicle's speed.
    bayer : bool
        A colour camera (RGGB Bayer mosaic, demosaiced: BGR images), else a monochrome one (grey).
    raw : bool
        A colour camera that writes its sensor's raw RGGB mosaic at 12 bits (one channel, uint16), as
        survey cameras do, instead of the demosaiced 8-bit colour image.
    """

    lamps_body_m: FloatArray = field(default_factory=lambda: np.array([[1.0, 0.0, 0.2], [-0.5, 0.0, 0.2]]))
    aim_body_m: FloatArray = field(default_factory=lambda: np.array([0.4, 0.0, 2.3]))
    beam_exponent: float = 2.5
    water: Water = field(default_factory=lambda: water_type("clear"))
    exposure: float = 130.0
    reference_altitude_m: float = 2.0
    full_well_e: float = FULL_WELL_E
    read_noise_e: float = READ_NOISE_E
    max_gain: float = 8.0
    flash_s: float = FLASH_S
    bayer: bool = True
    raw: bool = False

    def __post_init__(self) -> None:
        if self.raw and not self.bayer:
            raise ValueError("raw images need a colour (Bayer) camera")
        lamps = np.asarray(self.lamps_body_m)
        if lamps.ndim != 2 or lamps.shape[1] != 3 or lamps.shape[0] < 1:
            raise ValueError(f"lamps_body_m must have shape (k, 3), k >= 1; found {lamps.shape}")
        if np.shape(self.aim_body_m) != (3,):
            raise ValueError(f"aim_body_m must have shape (3,); found {np.shape(self.aim_body_m)}")
        if self.exposure <= 0 or self.full_well_e <= 0 or self.max_gain < 1:
            raise ValueError("exposure and full well must be positive, max_gain at least 1")
        if self.flash_s < 0 or self.read_noise_e < 0:
            raise ValueError("flash_s and read_noise_e must not be negative")

    def describe(self) -> dict[str, Any]:
        """Plain data for ``truth/imaging.yaml``."""
        return {
            "water": self.water.describe(),
            "lamps_body_m": np.asarray(self.lamps_body_m).round(4).tolist(),
            "aim_body_m": np.asarray(self.aim_body_m).round(4).tolist(),
            "beam_exponent": self.beam_exponent,
            "exposure_dn": self.exposure,
            "gain": round(_gain(self), 4),
            "full_well_e": self.full_well_e,
            "read_noise_e": self.read_noise_e,
            "flash_s": self.flash_s,
            "sensor": (
                "RGGB Bayer, raw 12-bit mosaic"
                if self.raw
                else "RGGB Bayer, demosaiced (OpenCV edge-aware)"
                if self.bayer
                else "monochrome"
            ),
            "forward_scatter": [{"sigma_rad": s, "fraction": f} for s, f in FORWARD_SCATTER],
        }


_RAY_CACHE: dict[tuple, NDArray] = {}


def _camera_key(cam: CameraModel) -> tuple:
    return (cam.width, cam.height, cam.K.tobytes(), np.asarray(cam.D, dtype=float).tobytes())


def _grid_rays(cam: CameraModel, step: int) -> FloatArray:
    """Rays (camera frame) of a grid of pixels every ``step`` pixels, one node beyond each side so that
    bicubic interpolation never reads outside the grid; cached per camera."""
    key = (*_camera_key(cam), step)
    if key not in _RAY_CACHE:
        cu = np.arange(-step, cam.width - 1 + 3 * step, step)
        cv_ = np.arange(-step, cam.height - 1 + 3 * step, step)
        if len(_RAY_CACHE) >= 8:  # a rig's two cameras at a time per process: keep memory bounded
            _RAY_CACHE.clear()
        _RAY_CACHE[key] = pixel_rays(cam, *np.meshgrid(cu, cv_))
    return _RAY_CACHE[key]


def _pixel_rays_f32(cam: CameraModel) -> NDArray[np.float32]:
    """Rays (camera frame, float32, H x W x 3) of every pixel; cached per camera."""
    key = (*_camera_key(cam), "full")
    if key not in _RAY_CACHE:
        if len(_RAY_CACHE) >= 8:
            _RAY_CACHE.clear()
        u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        _RAY_CACHE[key] = pixel_rays(cam, u, v).astype(np.float32)
    return _RAY_CACHE[key]


def _intersect(
    seafloor: SeafloorLike, c_ned: FloatArray, d_ned: FloatArray, iterations: int = 8
) -> FloatArray:
    """Ray lengths to the heightfield: fixed-point steps, then secant steps. d_ned: (..., 3) unit rays."""

    def residual(s: FloatArray) -> FloatArray:
        p = c_ned + s[..., None] * d_ned
        return p[..., 2] - seafloor.depth_m(p[..., 0], p[..., 1])

    dz = np.maximum(d_ned[..., 2], 0.05)
    s0 = np.maximum(
        (seafloor.depth_m(np.full(dz.shape, c_ned[0]), np.full(dz.shape, c_ned[1])) - c_ned[2]) / dz, 0.1
    )
    f0 = residual(s0)
    s1 = s0 - f0 / dz
    f1 = residual(s1)
    for _ in range(iterations):
        denom = f1 - f0
        ok = np.abs(denom) > 1e-12
        s2 = np.where(ok, s1 - f1 * (s1 - s0) / np.where(ok, denom, 1.0), s1 - f1 / dz)
        s0, f0, s1 = s1, f1, np.maximum(s2, 0.01)
        f1 = residual(s1)
        if np.max(np.abs(f1)) < 1e-6:
            break
    return s1


def render_view(
    seafloor: SeafloorLike,
    texture: SeafloorTexture,
    cam: CameraModel,
    T_ned_cam: FloatArray,
    T_ned_body: FloatArray,
    lighting: Lighting,
    rng: np.random.Generator,
    *,
    v_ned_mps: FloatArray | None = None,
) -> NDArray:
    """One image from a camera at ``T_ned_cam`` (4x4) on a vehicle at ``T_ned_body``.

    The image is formed as the Jaffe-McGlamery model has it (Jaffe 1990, "Computer modeling and the
    design of optimal underwater imaging systems", IEEE J. Oceanic Eng. 15(2)), in each of the red,
    green and blue bands: the strobes' light reaches the seafloor attenuated by ``exp(-K r)``
    (inverse-square falloff, beam pattern, Lambert's cosine), returns over the ray's length ``s``
    unscattered (``exp(-c s)``: the sharp image) or forward scattered (``exp(-K s) - exp(-c s)``:
    blurred by :data:`FORWARD_SCATTER`), and the water between adds the light it scatters back along
    the ray (:func:`_backscatter`); ``cos^4`` vignetting; the flash's motion blur when the vehicle's
    velocity ``v_ned_mps`` is given; then the sensor (:func:`_expose`).

    Geometry and light are computed exactly on a coarse grid of rays and interpolated bicubically to
    every pixel (both are smooth at that scale), except for a seafloor with depth discontinuities
    (one with an ``intersect_rays`` method, :class:`SteppedFloor`), whose every pixel is cast exactly.
    The albedo is evaluated at every pixel's hit point.

    Returns
    -------
    ndarray, uint8: (H, W, 3) BGR for a colour camera (``lighting.bayer``), else (H, W) grey;
    uint16 (H, W), the raw 12-bit RGGB mosaic, with ``lighting.raw``.
    """
    step = max(2, round(cam.width / COARSE_GRID_COLUMNS))
    coarse = _grid_rays(cam, step)
    R, c = T_ned_cam[:3, :3], T_ned_cam[:3, 3]
    d = coarse @ R.T
    exact = hasattr(seafloor, "intersect_rays")
    if exact:
        s, normal = seafloor.intersect_rays(c, d)
    else:
        s = _intersect(seafloor, c, d)
        p = c + s[..., None] * d
        normal = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        normal *= -np.sign(np.sum(normal * d, axis=-1, keepdims=True))  # face the camera
    scale = _dn_per_signal(lighting)
    vignetting = (coarse[..., 2] ** 4)[..., None]  # cos^4 of the angle off the optical axis
    veil = _backscatter(c, d, s, T_ned_body, lighting) * vignetting * scale
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float32), np.arange(cam.height, dtype=np.float32))
    mu, mv = u / step + 1, v / step + 1
    rays = _pixel_rays_f32(cam)
    if exact:
        # Every pixel exactly: lengths and light do not interpolate across a step.
        dd = rays.astype(float) @ R.T
        s_full, n_full = seafloor.intersect_rays(c, dd)
        p_full = c + s_full[..., None] * dd
        light = _irradiance(p_full.reshape(-1, 3), n_full.reshape(-1, 3), T_ned_body, lighting, seafloor)
        light = light.reshape(*s_full.shape, 3) * (rays[..., 2:] ** 4) * scale
        s_full = s_full.astype(np.float32)
        # A wall's texture runs down it: its height above the floor added along its normal.
        base = float(getattr(seafloor, "base_m", np.max(p_full[..., 2])))
        rise = np.maximum(base - p_full[..., 2], 0.0)[..., None]
        ne = p_full[..., :2] - c[:2] + rise * n_full[..., :2]
        light = light.astype(np.float32)
    else:
        p = c + s[..., None] * d
        light = _irradiance(p.reshape(-1, 3), normal.reshape(-1, 3), T_ned_body, lighting)
        light = light.reshape(*s.shape, 3) * vignetting * scale
        # To every pixel: the ray length and the light, then the hit point along each pixel's exact ray.
        # (Interpolating ray lengths, not positions: remap quantises its weights to 1/32 of a grid cell,
        # harmless for a length that varies by millimetres across a cell, not for positions.)
        fields = np.dstack([s, light]).astype(np.float32)
        full = cv2.remap(fields, mu, mv, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        s_full, light = full[..., 0], np.maximum(full[..., 1:], 0.0)
        ne = cv2.transform(rays, R[:2].astype(np.float32)) * s_full[..., None]
    footprint = float(np.median(s)) / cam.K[0, 0]
    albedo = texture.albedo_rgb(ne[..., 0] + c[0], ne[..., 1] + c[1], footprint_m=footprint)
    water = lighting.water
    # The light returning from the floor: unscattered, or forward scattered (spread about the ray).
    returned = albedo * light * np.exp(-water.K * s_full[..., None])
    sharp_fraction = np.exp(-(water.c - water.K) * s_full[..., None])
    radiance = returned * sharp_fraction
    scattered = returned - radiance
    for sigma_rad, fraction in FORWARD_SCATTER:
        radiance += _blur(scattered * np.float32(fraction), sigma_rad * cam.K[0, 0])
    radiance += cv2.remap(veil.astype(np.float32), mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if v_ned_mps is not None and lighting.flash_s > 0:
        radiance = _motion_blur(radiance, R, v_ned_mps, lighting.flash_s, cam.K[0, 0], float(np.median(s)))
    return _expose(radiance, lighting, rng)


def _blur(image: NDArray[np.float32], sigma_px: float) -> NDArray[np.float32]:
    """A Gaussian blur of ``sigma_px``, computed on the image reduced so that sigma is about 2 of its
    pixels (a wide blur costs what a narrow one does)."""
    h, w = image.shape[:2]
    f = max(1, int(sigma_px // 2))
    if f == 1:
        return cv2.GaussianBlur(image, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    small = cv2.resize(image, (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), sigma_px / f, borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def _motion_blur(
    image: NDArray[np.float32],
    R_ned_cam: FloatArray,
    v_ned_mps: FloatArray,
    flash_s: float,
    f_px: float,
    range_m: float,
) -> NDArray[np.float32]:
    """The image smeared along the vehicle's motion during the flash (translation of a camera
    ``range_m`` from the floor: the scene moves ``-f v / range`` pixels per second in the image)."""  # fmt: skip
    v_cam = R_ned_cam.T @ np.asarray(v_ned_mps, dtype=float)
    shift = -f_px * v_cam[:2] / max(range_m, 0.1) * flash_s  # (du, dv) during the flash, pixels
    length = float(np.hypot(*shift))
    if length < 0.05:
        return image
    n = int(np.ceil(length)) + 1
    size = 2 * n + 1
    kernel = np.zeros((size, size), dtype=np.float32)
    for t in np.linspace(-0.5, 0.5, 4 * n + 1):  # the path, splatted bilinearly
        x, y = n + t * shift[0], n + t * shift[1]
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        kernel[y0, x0] += (1 - fx) * (1 - fy)
        kernel[y0, x0 + 1] += fx * (1 - fy)
        kernel[y0 + 1, x0] += (1 - fx) * fy
        kernel[y0 + 1, x0 + 1] += fx * fy
    kernel /= kernel.sum()
    return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REFLECT)


def rggb_mosaic(rgb: NDArray) -> NDArray:
    """What an RGGB Bayer sensor samples of an image (H, W, 3; red, green, blue): one band per pixel,
    red at the top-left corner, blue diagonally below it, green at the other two (H, W; same dtype)."""
    out = np.empty(rgb.shape[:2], dtype=rgb.dtype)
    out[0::2, 0::2] = rgb[0::2, 0::2, 0]
    out[0::2, 1::2] = rgb[0::2, 1::2, 1]
    out[1::2, 0::2] = rgb[1::2, 0::2, 1]
    out[1::2, 1::2] = rgb[1::2, 1::2, 2]
    return out


#: A raw (12-bit) image's levels per 8-bit DN.
RAW_PER_DN = 16


def _expose(radiance: NDArray[np.float32], lighting: Lighting, rng: np.random.Generator) -> NDArray:
    """The sensor: electrons (shot noise), read noise, 8-bit quantisation; a colour camera samples one
    band per pixel through an RGGB Bayer mosaic and demosaics it (OpenCV's edge-aware interpolation),
    or (``lighting.raw``) gives the mosaic itself at 12 bits."""
    e_per_dn = lighting.full_well_e / 255.0 / _gain(lighting)
    if lighting.bayer:
        dn = rggb_mosaic(radiance)
    else:
        dn = radiance @ np.array(LUMA_RGB, dtype=np.float32)
    dn = np.maximum(dn, 0.0)
    sigma = np.sqrt(dn / np.float32(e_per_dn) + np.float32((lighting.read_noise_e / e_per_dn) ** 2))
    dn += sigma * rng.standard_normal(dn.shape, dtype=np.float32)
    if lighting.raw:
        return np.clip(np.rint(dn * np.float32(RAW_PER_DN)), 0, 4095).astype(np.uint16)
    raw = np.clip(np.rint(dn), 0, 255).astype(np.uint8)
    if not lighting.bayer:
        return raw
    # OpenCV names a Bayer pattern by the second row's second and third pixels: RGGB is its "BG".
    return cv2.cvtColor(raw, cv2.COLOR_BayerBG2BGR_EA)


def _lamps(T_ned_body: FloatArray, lighting: Lighting) -> list[tuple[FloatArray, FloatArray]]:
    """Each lamp's position and unit beam axis, local NED."""
    R, t = T_ned_body[:3, :3], T_ned_body[:3, 3]
    aim = R @ np.asarray(lighting.aim_body_m, dtype=float) + t
    out = []
    for lamp_body in np.asarray(lighting.lamps_body_m, dtype=float):
        lamp = R @ lamp_body + t
        axis = aim - lamp
        out.append((lamp, axis / np.linalg.norm(axis)))
    return out


def _irradiance(
    p_ned: FloatArray,
    n_ned: FloatArray,
    T_ned_body: FloatArray,
    lighting: Lighting,
    scene: Any = None,
) -> NDArray[np.float32]:
    """Strobe irradiance (N, 3) in the red, green and blue bands at points (N, 3) with unit normals
    (N, 3), unnormalised: beam pattern, Lambert's cosine, inverse square, ``exp(-K r)``; shadows when
    ``scene`` has a ``shadowed`` method."""
    K = lighting.water.K.astype(float)
    total = np.zeros((p_ned.shape[0], 3))
    for lamp, axis in _lamps(T_ned_body, lighting):
        to_lamp = lamp - p_ned
        r2 = np.einsum("ij,ij->i", to_lamp, to_lamp)
        r = np.sqrt(r2)
        lambert = np.maximum(np.einsum("ij,ij->i", n_ned, to_lamp) / r, 0.0)
        beam = np.maximum(-(to_lamp @ axis) / r, 0.0) ** lighting.beam_exponent
        e = beam * lambert / r2
        if scene is not None and hasattr(scene, "shadowed"):
            e = np.where(scene.shadowed(p_ned, lamp), 0.0, e)
        total += e[:, None] * np.exp(-K * r[:, None])
    return total.astype(np.float32)


def _backscatter(
    c_ned: FloatArray, d_ned: FloatArray, s: FloatArray, T_ned_body: FloatArray, lighting: Lighting
) -> FloatArray:
    """Light the water scatters back into each ray (..., 3) (single scattering, midpoint rule over
    :data:`BACKSCATTER_SAMPLES` points): ``int_0^s beta E_lamp(z) exp(-K z) dz``, the phase function
    taken flat over the backward hemisphere (``beta = b_b / 2 pi``), in the unit of :func:`_irradiance`
    times ``pi`` per unit albedo (a Lambertian floor's radiance is ``albedo E / pi``)."""
    water = lighting.water
    K = water.K.astype(float)
    out = np.zeros((*s.shape, 3))
    dz = s / BACKSCATTER_SAMPLES
    for k in range(BACKSCATTER_SAMPLES):
        z = (k + 0.5) * dz
        q = c_ned + z[..., None] * d_ned
        for lamp, axis in _lamps(T_ned_body, lighting):
            to_lamp = lamp - q
            r2 = np.sum(to_lamp * to_lamp, axis=-1)
            r = np.sqrt(r2)
            beam = np.maximum(-(to_lamp @ axis) / r, 0.0) ** lighting.beam_exponent
            e = (beam / np.maximum(r2, 1e-4) * dz)[..., None] * np.exp(-K * (r + z)[..., None])
            out += e
    return out * (water.bb.astype(float) / (2.0 * np.pi) * np.pi)


def _reference_signal(lighting: Lighting) -> float:
    """Green-band signal of a 0.5-albedo flat floor straight below a level camera at the reference
    altitude (the cameras sit 0.4 m forward of and 0.3 m below the body origin)."""
    camera = np.array([0.4, 0.0, 0.3])
    p = camera + np.array([[0.0, 0.0, lighting.reference_altitude_m]])
    e = _irradiance(p, np.array([[0.0, 0.0, -1.0]]), np.eye(4), lighting)[0, 1]
    return float(0.5 * e * np.exp(-lighting.water.K[1] * lighting.reference_altitude_m))


def _gain(lighting: Lighting) -> float:
    """The camera's gain over its base: what brings the reference (:func:`_reference_signal`) to
    ``exposure`` DN with the strobes' energy fixed by the clear water's reference, capped at
    ``max_gain`` (1 in the clear water of :func:`water_type`)."""
    clear = _reference_signal(dataclasses.replace(lighting, water=water_type("clear")))
    return float(np.clip(clear / _reference_signal(lighting), 1.0, lighting.max_gain))


def _dn_per_signal(lighting: Lighting) -> float:
    """Digital numbers per unit of :func:`_irradiance` signal, at the camera's gain."""
    clear = _reference_signal(dataclasses.replace(lighting, water=water_type("clear")))
    return lighting.exposure / clear * _gain(lighting)


def camera_poses(rig: StereoRig, T_ned_body: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``T_ned_left``, ``T_ned_right`` (4x4) of the rig on a body at ``T_ned_body``."""
    T_body_left = se3(rig.mount.R_body_sensor, rig.mount.lever_arm_body_m)
    T_right_left = se3(rig.R_right_left, rig.t_right_left_m)
    T_ned_left = T_ned_body @ T_body_left
    return T_ned_left, T_ned_left @ se3_inverse(T_right_left)


def render_stereo_pair(
    seafloor: SeafloorLike,
    texture: SeafloorTexture,
    rig: StereoRig,
    T_ned_body: FloatArray,
    *,
    lighting: Lighting | None = None,
    rng: np.random.Generator | None = None,
    v_ned_mps: FloatArray | None = None,
) -> tuple[NDArray, NDArray]:
    """Render the left and right images of a stereo rig on a vehicle at ``T_ned_body``.

    Parameters
    ----------
    seafloor : object with ``depth_m(north_m, east_m)``
        Seafloor depth, positive down, metres, local NED.
    texture : SeafloorTexture
    rig : StereoRig
        Calibration of the images to produce (use :func:`scale_camera_rig` for smaller images).
    T_ned_body : ndarray, shape (4, 4)
        Pose of the body (FRD) in local NED.
    lighting : Lighting, optional
    rng : numpy Generator, optional
        Sensor noise; seeded 0 when omitted.
    v_ned_mps : ndarray, shape (3,), optional
        The vehicle's velocity, m/s, local NED: motion blur during the flash (none when omitted).

    Returns
    -------
    left, right : ndarray, uint8, shape (height, width, 3) BGR (colour camera, the default) or
        (height, width) (``lighting.bayer`` False); uint16 (height, width) raw mosaics (``lighting.raw``)
    """
    lighting = lighting or Lighting()
    rng = rng or np.random.default_rng(0)
    T_left, T_right = camera_poses(rig, T_ned_body)
    left = render_view(seafloor, texture, rig.left, T_left, T_ned_body, lighting, rng, v_ned_mps=v_ned_mps)
    right = render_view(seafloor, texture, rig.right, T_right, T_ned_body, lighting, rng, v_ned_mps=v_ned_mps)
    return left, right


def to_grey(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A rendered image as 8-bit grey (BGR to luminance as ``cv2.imread(..., IMREAD_GRAYSCALE)`` does)."""
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def body_poses(traj: Trajectory) -> FloatArray:
    """``T_ned_body`` (N, 4, 4) of a trajectory."""
    return se3(traj.R_ned_body, traj.p_ned_m)


def select_image_times(
    truth: Trajectory,
    seafloor: SeafloorLike,
    *,
    rate_hz: float = 1.0,
    min_altitude_m: float = 0.5,
    max_altitude_m: float = 4.0,
) -> FloatArray:
    """Camera trigger times: every ``1 / rate_hz`` seconds while the vehicle is within imaging altitude."""
    if rate_hz <= 0:
        raise ValueError(f"rate_hz must be positive; found {rate_hz}")
    t = np.arange(truth.t_s[0], truth.t_s[-1], 1.0 / rate_hz)
    p = truth.interpolate(t).p_ned_m
    altitude = seafloor.depth_m(p[:, 0], p[:, 1]) - p[:, 2]
    return t[(altitude >= min_altitude_m) & (altitude <= max_altitude_m)]


@dataclass(frozen=True)
class _RenderJob:
    seafloor: SeafloorLike
    texture: SeafloorTexture
    rig: StereoRig
    lighting: Lighting
    seed: int
    out_dir: Path


def _render_chunk(job: _RenderJob, items: list[tuple[int, FloatArray, FloatArray]]) -> list[int]:
    for k, T_ned_body, v_ned_mps in items:
        _render_one(job, k, T_ned_body, v_ned_mps)
    return [item[0] for item in items]


def _render_one(job: _RenderJob, k: int, T_ned_body: FloatArray, v_ned_mps: FloatArray) -> None:
    rng = np.random.default_rng([job.seed, k])
    left, right = render_stereo_pair(
        job.seafloor, job.texture, job.rig, T_ned_body, lighting=job.lighting, rng=rng, v_ned_mps=v_ned_mps
    )
    for name, img in ((image_names(k)[0], left), (image_names(k)[1], right)):
        path = job.out_dir / name
        tmp = path.with_name(f".{path.name}.tmp.png")
        if not cv2.imwrite(str(tmp), img, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
            raise OSError(f"could not write {path}")
        tmp.replace(path)


def image_names(k: int) -> tuple[str, str]:
    """File names (relative to ``images/``) of the k-th stereo pair."""
    return f"left/{k:06d}.png", f"right/{k:06d}.png"


def render_images(
    truth: Trajectory,
    seafloor: SeafloorLike,
    rig: StereoRig,
    times_s: FloatArray,
    out_dir: Path,
    *,
    texture: SeafloorTexture | None = None,
    lighting: Lighting | None = None,
    seed: int = 0,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ImageIndex:
    """Render stereo pairs at ``times_s`` along the true trajectory and write ``images/``.

    Parameters
    ----------
    truth : Trajectory
        The true vehicle trajectory (interpolated to the image times).
    seafloor : object with ``depth_m(north_m, east_m)``
    rig : StereoRig
        The calibration of the images written (scaled for smaller images: :func:`scale_camera_rig`).
    times_s : ndarray, shape (N,)
        Trigger times, POSIX seconds, strictly increasing, inside the trajectory.
    out_dir : Path
        The dive's ``images/`` folder; ``left/``, ``right/`` and ``index.csv`` are written in it.
    texture : SeafloorTexture, optional
        Seeded with ``seed`` when omitted.
    seed : int
        Seeds the texture (when not given) and the sensor noise of every image.
    executor : Executor, optional
        Runs the rendering (default: in this process).
    progress : callable(done, total), optional

    Returns
    -------
    ImageIndex
        Also written to ``out_dir / "index.csv"``.
    """
    out_dir = Path(out_dir)
    times_s = np.asarray(times_s, dtype=float)
    (out_dir / "left").mkdir(parents=True, exist_ok=True)
    (out_dir / "right").mkdir(parents=True, exist_ok=True)
    poses = body_poses(truth.interpolate(times_s))
    velocities = _velocities(truth, times_s)
    job = _RenderJob(
        seafloor, texture or SeafloorTexture(seed=seed), rig, lighting or Lighting(), seed, out_dir
    )
    total = len(times_s)
    done = 0
    items = [(k, pose, v) for k, (pose, v) in enumerate(zip(poses, velocities, strict=True))]
    for rendered in (executor or SerialExecutor()).map(_render_chunk, job, chunks(items, 2)):
        done += len(rendered)
        if progress:
            progress(done, total)
    names = [image_names(k) for k in range(total)]
    index = ImageIndex(
        times_s, np.array([a for a, _ in names], dtype=str), np.array([b for _, b in names], dtype=str)
    )
    write_stream(index, out_dir / "index.csv")
    log.info("rendered %d stereo pairs into %s", total, out_dir)
    return index


def _velocities(truth: Trajectory, times_s: FloatArray, dt_s: float = 0.05) -> FloatArray:
    """The true velocity (N, 3), m/s, local NED, at ``times_s``: central differences over ``2 dt_s``
    (one-sided at the ends of the trajectory)."""
    if len(times_s) == 0:
        return np.zeros((0, 3))
    lo = np.maximum(times_s - dt_s, truth.t_s[0])
    hi = np.minimum(times_s + dt_s, truth.t_s[-1])
    span = np.maximum(hi - lo, 1e-9)[:, None]
    return (truth.interpolate(hi).p_ned_m - truth.interpolate(lo).p_ned_m) / span


def seafloor_from_truth(truth_yaml: Path) -> SeafloorLike:
    """The simulated seafloor of a dive, rebuilt from ``truth/truth.yaml`` (its seed and parameters)."""
    import yaml

    from auvnav.errors import ConfigError
    from auvnav.sim.seafloor import Seafloor, SeafloorParams

    try:
        data = yaml.safe_load(Path(truth_yaml).read_text(encoding="utf-8"))
        params = dict(data["seafloor"])
        seed = int(params.pop("seed"))
        params = {k: tuple(v) if isinstance(v, list) else v for k, v in params.items()}
        return Seafloor(seed, SeafloorParams(**params))
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as err:
        raise ConfigError(
            f"{truth_yaml}: no usable seafloor description ({type(err).__name__}: {err})"
        ) from err


@dataclass(frozen=True)
class SteppedFloor:
    """A level floor with raised flat-topped blocks (ledges, boulders): depth discontinuities.

    The procedural reef (:class:`~auvnav.sim.seafloor.Seafloor`) is smooth; this scene has the steps
    where a stereo patch straddles two depths. The renderer casts its every pixel exactly
    (:meth:`intersect_rays`) and its blocks cast the strobes' shadows (:meth:`shadowed`).

    Parameters
    ----------
    base_m : float
        Depth of the floor, metres, positive down.
    blocks : tuple of (north_min, north_max, east_min, east_max, height_m)
        Axis-aligned blocks standing on the floor, metres, local NED.
    """

    base_m: float
    blocks: tuple[tuple[float, float, float, float, float], ...] = ()

    @classmethod
    def random(
        cls,
        seed: int,
        base_m: float,
        centre_ne_m: tuple[float, float] = (0.0, 0.0),
        *,
        extent_m: float = 3.0,
        count: int = 14,
        heights_m: tuple[float, float] = (0.05, 0.35),
        sizes_m: tuple[float, float] = (0.15, 0.7),
    ) -> SteppedFloor:
        """``count`` blocks of random size and height scattered over a square ``extent_m`` wide."""
        rng = np.random.default_rng(seed)
        blocks = []
        for _ in range(count):
            n, e = np.asarray(centre_ne_m) + rng.uniform(-extent_m / 2, extent_m / 2, 2)
            ln, le = rng.uniform(*sizes_m, 2)
            blocks.append((n - ln / 2, n + ln / 2, e - le / 2, e + le / 2, float(rng.uniform(*heights_m))))
        return cls(base_m, tuple(tuple(float(x) for x in b) for b in blocks))  # type: ignore[misc]

    def depth_m(self, north_m: FloatArray, east_m: FloatArray) -> FloatArray:
        n, e = np.broadcast_arrays(np.asarray(north_m, dtype=float), np.asarray(east_m, dtype=float))
        depth = np.full(n.shape, float(self.base_m))
        for n0, n1, e0, e1, h in self.blocks:
            inside = (n >= n0) & (n <= n1) & (e >= e0) & (e <= e1)
            depth = np.where(inside, np.minimum(depth, self.base_m - h), depth)
        return depth

    def _boxes(self) -> list[tuple[FloatArray, FloatArray]]:
        return [
            (np.array([n0, e0, self.base_m - h]), np.array([n1, e1, self.base_m]))
            for n0, n1, e0, e1, h in self.blocks
        ]

    @staticmethod
    def _slabs(
        c: FloatArray, d: FloatArray, lo: FloatArray, hi: FloatArray
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Entry and exit parameters of rays ``c + t d`` through a box, and the axis of entry."""
        safe = np.where(np.abs(d) < 1e-12, 1e-12, d)
        t1, t2 = (lo - c) / safe, (hi - c) / safe
        near, far = np.minimum(t1, t2), np.maximum(t1, t2)
        return near.max(axis=-1), far.min(axis=-1), near.argmax(axis=-1)

    def intersect_rays(self, c_ned: FloatArray, d_ned: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Ray lengths (...) to the first surface and its unit normal (..., 3), facing the rays."""
        d = np.asarray(d_ned, dtype=float)
        dz = d[..., 2]
        s = np.where(dz > 1e-9, (self.base_m - c_ned[2]) / np.where(dz > 1e-9, dz, 1.0), np.inf)
        normal = np.zeros(d.shape)
        normal[..., 2] = -1.0
        for lo, hi in self._boxes():
            near, far, axis = self._slabs(c_ned, d, lo, hi)
            hit = (near <= far) & (near > 0) & (near < s)
            s = np.where(hit, near, s)
            face = np.zeros(d.shape)
            np.put_along_axis(face, axis[..., None], 1.0, axis=-1)
            face *= -np.sign(np.take_along_axis(d, axis[..., None], axis=-1))
            normal = np.where(hit[..., None], face, normal)
        return s, normal

    def shadowed(self, p_ned: FloatArray, lamp_ned: FloatArray) -> NDArray[np.bool_]:
        """Whether a block stands between points (N, 3) and a lamp."""
        d = lamp_ned - p_ned
        out = np.zeros(len(p_ned), dtype=bool)
        for lo, hi in self._boxes():
            near, far, _ = self._slabs(p_ned, d, lo, hi)
            out |= (near <= far) & (far > 1e-4) & (near < 1.0) & (near > 1e-4)
        return out


def render_dive_images(
    dive_path: Path,
    *,
    scale: float = 1.0,
    rate_hz: float = 1.0,
    rig: StereoRig | None = None,
    seed: int = 0,
    water: WaterName = "clear",
    raw: bool = False,
    lighting: Lighting | None = None,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ImageIndex:
    """Render the images of a simulated dive folder and record their calibration.

    Reads ``truth/trajectory.csv`` and the seafloor of ``truth/truth.yaml``, renders stereo pairs at
    ``rate_hz`` while the vehicle is within imaging altitude, writes ``images/`` with ``index.csv``,
    writes the rig, scaled to the images (``scale``), into the dive's vehicle file, and the image
    formation (water, strobes, sensor, texture) into ``truth/imaging.yaml``.

    Parameters
    ----------
    dive_path : Path
        A dive folder written by the simulator.
    scale : float
        Image size relative to the rig's (1360 x 1024 for :func:`default_stereo_rig`).
    rate_hz : float
        Camera trigger rate.
    rig : StereoRig, optional
        Default :func:`default_stereo_rig`.
    seed : int
        Sensor noise. The texture is the site's: seeded by the seafloor's seed of ``truth/truth.yaml``
        (the dive's own seed, or for a repeat survey the site's), so that dives of one site see the
        same seafloor in the same (site) coordinates.
    water : {"clear", "coastal", "turbid"}
        The water (:func:`water_type`), unless ``lighting`` is given.
    raw : bool
        Raw 12-bit RGGB mosaics (:attr:`Lighting.raw`), unless ``lighting`` is given.
    lighting : Lighting, optional
        Strobes, water and sensor (default: :class:`Lighting` in ``water``).
    executor : Executor, optional
        Runs the rendering (default: in this process).
    progress : callable(done, total), optional
    """
    from auvnav.config import dump_yaml
    from auvnav.dive import vehicle_file_name
    from auvnav.streams import atomic_write
    from auvnav.trajectory import read_trajectory
    from auvnav.vehicle import read_vehicle, write_vehicle

    dive_path = Path(dive_path)
    truth = read_trajectory(dive_path / "truth" / "trajectory.csv")
    seafloor = seafloor_from_truth(dive_path / "truth" / "truth.yaml")
    rig = scale_camera_rig(rig or default_stereo_rig(), scale)
    times = select_image_times(truth, seafloor, rate_hz=rate_hz)
    lighting = lighting or Lighting(water=water_type(water), raw=raw)
    texture = SeafloorTexture(seed=int(getattr(seafloor, "seed", seed)))  # the site's
    index = render_images(
        truth,
        seafloor,
        rig,
        times,
        dive_path / "images",
        texture=texture,
        lighting=lighting,
        seed=seed,
        executor=executor,
        progress=progress,
    )
    imaging = {
        "format": "auvnav-imaging/1",
        **lighting.describe(),
        "texture": dataclasses.asdict(texture),
        "image_scale": scale,
        "rate_hz": rate_hz,
    }
    text = dump_yaml(imaging)
    atomic_write(dive_path / "truth" / "imaging.yaml", lambda p: p.write_text(text, encoding="utf-8"))
    vehicle_file = dive_path / (vehicle_file_name(dive_path) or "vehicle.yaml")
    if lighting.raw:  # the vehicle file names the cameras' colour filter
        rig = rig.with_bayer("rggb", "rggb")
    write_vehicle(dataclasses.replace(read_vehicle(vehicle_file), stereo=rig), vehicle_file)
    return index
