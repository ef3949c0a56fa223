"""Stereo rendering of the procedural seafloor: calibrated down-looking pairs by ray casting.

Each pixel's ray (through the lens distortion of the calibration) is intersected with the seafloor
heightfield ``depth_m(north, east)``: fixed-point and secant iterations on a coarse grid of pixels, the
ray length interpolated bicubically to every pixel (the seafloor is smooth at the scale of centimetres). The hit point's albedo comes from :class:`~auvnav.sim.texture.SeafloorTexture`
in world coordinates, and the light is a strobe's: inverse-square falloff from each lamp, the lamp's
beam pattern, Lambert's cosine on the surface normal, attenuation ``exp(-c * path)`` on the way down
and back, ``cos^4`` vignetting, then shot and read noise and 8-bit quantisation.

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

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.dive import ImageIndex
from auvnav.executor import Executor, SerialExecutor, chunks
from auvnav.footprint import SeafloorLike
from auvnav.frames import se3, se3_inverse
from auvnav.sim.texture import SeafloorTexture
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
# read noise of such CCD cameras is ~10-15 electrons, i.e. ~0.2 DN at 8 bits.
FULL_WELL_E = 18000.0
READ_NOISE_DN = 0.2
# Diffuse attenuation of clear tropical coastal water at green wavelengths, ~0.1-0.3 1/m; the beam
# attenuation c is larger (Mobley 1994, "Light and Water", ch. 3). 0.3 1/m is used for the light path.
ATTENUATION_PER_M = 0.3

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
class Lighting:
    """Strobes, water and sensor.

    Parameters
    ----------
    lamps_body_m : ndarray, shape (k, 3)
        Lamp positions, metres, body FRD (Sirius carries two strobes fore and aft of the cameras).
    beam_exponent : float
        Lamp beam pattern ``cos(angle from body down) ** beam_exponent``.
    attenuation_per_m : float
        Water attenuation coefficient, 1/m, applied over lamp-to-seafloor and seafloor-to-camera paths.
    exposure : float
        Digital number of a 0.5-albedo flat seafloor straight below the camera at ``reference_altitude_m``.
    reference_altitude_m : float
        Altitude at which ``exposure`` holds (the survey altitude).
    full_well_e, read_noise_dn : float
        Sensor shot noise (electrons for 255 DN) and read noise, DN.
    backscatter_dn : float
        A uniform veil from light scattered by the water column, DN.
    """

    lamps_body_m: FloatArray = field(default_factory=lambda: np.array([[1.0, 0.0, 0.2], [-0.5, 0.0, 0.2]]))
    beam_exponent: float = 1.5
    attenuation_per_m: float = ATTENUATION_PER_M
    exposure: float = 130.0
    reference_altitude_m: float = 2.0
    full_well_e: float = FULL_WELL_E
    read_noise_dn: float = READ_NOISE_DN
    backscatter_dn: float = 4.0

    def __post_init__(self) -> None:
        lamps = np.asarray(self.lamps_body_m)
        if lamps.ndim != 2 or lamps.shape[1] != 3 or lamps.shape[0] < 1:
            raise ValueError(f"lamps_body_m must have shape (k, 3), k >= 1; found {lamps.shape}")
        if self.attenuation_per_m < 0 or self.exposure <= 0 or self.full_well_e <= 0:
            raise ValueError("attenuation must be >= 0, exposure and full well positive")


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
) -> NDArray[np.uint8]:
    """One 8-bit grey image from a camera at ``T_ned_cam`` (4x4) on a vehicle at ``T_ned_body``.

    Geometry and light are computed exactly on the coarse grid of rays and interpolated bicubically to
    every pixel (both are smooth at that scale); the albedo is evaluated at every pixel's hit point.
    """
    step = max(2, round(cam.width / COARSE_GRID_COLUMNS))
    coarse = _grid_rays(cam, step)
    R, c = T_ned_cam[:3, :3], T_ned_cam[:3, 3]
    d = coarse @ R.T
    s = _intersect(seafloor, c, d)
    p = c + s[..., None] * d
    normal = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal *= -np.sign(np.sum(normal * d, axis=-1, keepdims=True))  # face the camera
    shape = p.shape[:2]
    light = _irradiance(p.reshape(-1, 3), normal.reshape(-1, 3), T_ned_body, lighting).reshape(shape)
    light *= (
        np.exp(-lighting.attenuation_per_m * s) * coarse[..., 2] ** 4
    )  # water path back, cos^4 vignetting
    light *= lighting.exposure / _reference_radiance(lighting)
    # To every pixel: the ray length and the light, then the hit point along each pixel's exact ray.
    # (Interpolating ray lengths, not positions: remap quantises its weights to 1/32 of a grid cell,
    # harmless for a length that varies by millimetres across a cell, not for positions.)
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float32), np.arange(cam.height, dtype=np.float32))
    mu, mv = u / step + 1, v / step + 1
    fields = np.dstack([s, light]).astype(np.float32)
    full = cv2.remap(fields, mu, mv, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    ne = cv2.transform(_pixel_rays_f32(cam), R[:2].astype(np.float32)) * full[..., :1]
    footprint = float(np.median(s)) / cam.K[0, 0]
    albedo = texture.albedo(ne[..., 0] + c[0], ne[..., 1] + c[1], footprint_m=footprint)
    dn = albedo * full[..., 1] + np.float32(lighting.backscatter_dn)
    gain = np.float32(255.0 / lighting.full_well_e)  # DN per electron
    sigma = np.sqrt(np.maximum(dn, 0.0) * gain + np.float32(lighting.read_noise_dn**2))
    dn += sigma * rng.standard_normal(dn.shape, dtype=np.float32)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def _irradiance(
    p_ned: FloatArray, n_ned: FloatArray, T_ned_body: FloatArray, lighting: Lighting
) -> FloatArray:
    """Strobe irradiance at points (N, 3) with unit normals (N, 3): sum over lamps, unnormalised."""
    R, t = T_ned_body[:3, :3], T_ned_body[:3, 3]
    down = R[:, 2]
    total = np.zeros(p_ned.shape[0])
    for lamp_body in np.asarray(lighting.lamps_body_m):
        lamp = R @ lamp_body + t
        to_lamp = lamp - p_ned
        r2 = np.einsum("ij,ij->i", to_lamp, to_lamp)
        r = np.sqrt(r2)
        lambert = np.maximum(np.einsum("ij,ij->i", n_ned, to_lamp) / r, 0.0)
        beam = np.maximum(-(to_lamp @ down) / r, 0.0) ** lighting.beam_exponent
        total += beam * lambert * np.exp(-lighting.attenuation_per_m * r) / r2
    return total


def _reference_radiance(lighting: Lighting) -> float:
    """Radiance of a 0.5-albedo flat floor straight below a level camera at the reference altitude."""
    a = lighting.reference_altitude_m
    p = np.array([[0.0, 0.0, a]])
    return float(
        0.5
        * _irradiance(p, np.array([[0.0, 0.0, -1.0]]), np.eye(4), lighting)[0]
        * np.exp(-lighting.attenuation_per_m * a)
    )


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
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
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

    Returns
    -------
    left, right : ndarray, shape (height, width), uint8
    """
    lighting = lighting or Lighting()
    rng = rng or np.random.default_rng(0)
    T_left, T_right = camera_poses(rig, T_ned_body)
    left = render_view(seafloor, texture, rig.left, T_left, T_ned_body, lighting, rng)
    right = render_view(seafloor, texture, rig.right, T_right, T_ned_body, lighting, rng)
    return left, right


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


def _render_chunk(job: _RenderJob, items: list[tuple[int, FloatArray]]) -> list[int]:
    for k, T_ned_body in items:
        _render_one(job, k, T_ned_body)
    return [k for k, _ in items]


def _render_one(job: _RenderJob, k: int, T_ned_body: FloatArray) -> None:
    rng = np.random.default_rng([job.seed, k])
    left, right = render_stereo_pair(
        job.seafloor, job.texture, job.rig, T_ned_body, lighting=job.lighting, rng=rng
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
    job = _RenderJob(
        seafloor, texture or SeafloorTexture(seed=seed), rig, lighting or Lighting(), seed, out_dir
    )
    total = len(times_s)
    done = 0
    for rendered in (executor or SerialExecutor()).map(_render_chunk, job, chunks(list(enumerate(poses)), 2)):
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


def render_dive_images(
    dive_path: Path,
    *,
    scale: float = 1.0,
    rate_hz: float = 1.0,
    rig: StereoRig | None = None,
    seed: int = 0,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ImageIndex:
    """Render the images of a simulated dive folder and record their calibration.

    Reads ``truth/trajectory.csv`` and the seafloor of ``truth/truth.yaml``, renders stereo pairs at
    ``rate_hz`` while the vehicle is within imaging altitude, writes ``images/`` with ``index.csv``,
    and writes the rig, scaled to the images (``scale``), into the dive's vehicle file.

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
        Texture and sensor noise.
    executor : Executor, optional
        Runs the rendering (default: in this process).
    progress : callable(done, total), optional
    """
    import dataclasses

    from auvnav.dive import vehicle_file_name
    from auvnav.trajectory import read_trajectory
    from auvnav.vehicle import read_vehicle, write_vehicle

    dive_path = Path(dive_path)
    truth = read_trajectory(dive_path / "truth" / "trajectory.csv")
    seafloor = seafloor_from_truth(dive_path / "truth" / "truth.yaml")
    rig = scale_camera_rig(rig or default_stereo_rig(), scale)
    times = select_image_times(truth, seafloor, rate_hz=rate_hz)
    index = render_images(
        truth, seafloor, rig, times, dive_path / "images", seed=seed, executor=executor, progress=progress
    )
    vehicle_file = dive_path / (vehicle_file_name(dive_path) or "vehicle.yaml")
    write_vehicle(dataclasses.replace(read_vehicle(vehicle_file), stereo=rig), vehicle_file)
    return index
