"""The paper's figures re-made from a dive's products (matplotlib lives in ``report/`` only).

Each ``fig*`` function draws one figure from the products of one dive into a PNG and returns its
caption; when the products it needs are absent it raises :class:`NotDrawn` with the reason (which
stage did not run, or what the dive lacks), so that the report says why instead of leaving an empty
box. :func:`draw_figures` draws them all and returns one :class:`Panel` per figure.

A simulated dive's truth (``truth/trajectory.csv``, the true deviation) is drawn beside the products
where the paper would compare against it; nothing here scores a product against the truth (that is
``auvnav evaluate``).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from auvnav import products as P
from auvnav.errors import AuvnavError
from auvnav.frames import angle_diff
from auvnav.streams import atomic_write
from auvnav.trajectory import Trajectory, read_trajectory

log = logging.getLogger(__name__)

TRUTH_TRAJECTORY = Path("truth") / "trajectory.csv"
DPI = 100
#: At most this many points of a track are drawn (plots of 20,000 samples look the same thinned).
MAX_TRACK_POINTS = 4000


class NotDrawn(Exception):
    """A figure's products are absent; the message says why (for the report's line)."""


@dataclass(frozen=True)
class Panel:
    """One figure of the report: its PNG (``file``, inside the figures folder) or why it is absent.

    Parameters
    ----------
    key : str
        Short name, e.g. ``fig2``.
    title : str
        What the figure shows, with the paper's figure number.
    file : str or None
        The PNG's name when drawn.
    caption : str
        One sentence about what was drawn (empty when not drawn).
    why : str or None
        Why it was not drawn.
    """

    key: str
    title: str
    file: str | None = None
    caption: str = ""
    why: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "title": self.title,
            "file": self.file,
            "caption": self.caption,
            "why": self.why,
        }


def _save(fig: Any, path: Path) -> None:
    atomic_write(Path(path), lambda p: fig.savefig(p, dpi=DPI, format="png"))
    plt.close(fig)


def _thin(n: int, most: int = MAX_TRACK_POINTS) -> slice:
    return slice(None, None, max(1, int(np.ceil(n / most))))


def _trajectory(dive: Path, product: P.Product, why: str) -> Trajectory:
    path = product.path(dive)
    if not path.is_file():
        raise NotDrawn(why)
    return read_trajectory(path)


def _truth(dive: Path) -> Trajectory | None:
    path = Path(dive) / TRUTH_TRAJECTORY
    return read_trajectory(path) if path.is_file() else None


def _json(product: P.Product, dive: Path) -> dict[str, Any] | None:
    path = product.path(dive)
    if not path.is_file():
        return None
    data = json.loads(path.read_text(encoding="utf-8"))
    return data if isinstance(data, dict) else None


def loops_file(dive: Path) -> Path | None:
    """The loop closures SLAM used: the vision stage's, else the file SLAM was given (its summary)."""
    if P.LOOPS.path(dive).is_file():
        return P.LOOPS.path(dive)
    path = P.SLAM_SUMMARY.path(dive)
    if not path.is_file():
        return None
    given = (json.loads(path.read_text(encoding="utf-8")).get("loops") or {}).get("file")
    if not given:
        return None
    given = Path(given) if Path(given).is_absolute() else dive / given
    return given if given.is_file() else None


NO_NAV = "no navigation products (products/nav: the nav stage did not run)"
NO_SLAM = "no SLAM trajectory (products/slam: the slam stage did not run or found no loop closures)"


# ---------------------------------------------------------------------------------------------
# Fig. 2: dead reckoning against SLAM
# ---------------------------------------------------------------------------------------------


def fig2_paths(dive: Path, path: Path) -> str:
    """Plan view of the dead-reckoned, filtered and SLAM tracks (and the truth when simulated)."""
    dr = _trajectory(dive, P.NAV_DR, NO_NAV)
    tracks: list[tuple[str, Trajectory, dict[str, Any]]] = [("dead reckoning", dr, {"c": "tab:red"})]
    if P.NAV_FILTER.path(dive).is_file():
        tracks.append(("filter (GPS)", read_trajectory(P.NAV_FILTER.path(dive)), {"c": "tab:orange"}))
    slam = read_trajectory(P.SLAM_TRAJECTORY.path(dive)) if P.SLAM_TRAJECTORY.path(dive).is_file() else None
    if slam is not None:
        tracks.append(("SLAM", slam, {"c": "tab:blue"}))
    truth = _truth(dive)
    if truth is not None:
        tracks.append(("truth", truth, {"c": "k", "ls": "--", "lw": 0.6}))
    fig, ax = plt.subplots(figsize=(7, 6))
    for label, traj, style in tracks:
        s = _thin(len(traj))
        ax.plot(traj.p_ned_m[s, 1], traj.p_ned_m[s, 0], lw=style.pop("lw", 0.9), label=label, **style)
    ax.plot(dr.p_ned_m[0, 1], dr.p_ned_m[0, 0], "k^", ms=6, label="start")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_title("dead reckoning" + (" and SLAM" if slam is not None else "") + " (plan view)")
    fig.tight_layout()
    _save(fig, path)
    end = np.linalg.norm(dr.p_ned_m[-1, :2] - slam.p_ned_m[-1, :2]) if slam is not None else None
    return (
        f"{len(tracks)} tracks; "
        + (f"dead reckoning ends {end:.2f} m from SLAM" if end is not None else "no SLAM")
    ) + ("" if truth is None else "; dashed: the simulator's truth")


# ---------------------------------------------------------------------------------------------
# Fig. 4: compass against SLAM headings, with the loop closures
# ---------------------------------------------------------------------------------------------


def fig4_headings(dive: Path, path: Path) -> str:
    """Compass and SLAM headings against time (top), their difference with the loop-closure times
    marked (bottom)."""
    slam = _trajectory(dive, P.SLAM_TRAJECTORY, NO_SLAM)
    pairs_path = P.COMPASS_PAIRS.path(dive)
    if pairs_path.is_file():
        pairs = pd.read_csv(pairs_path)
        t = pairs["t"].to_numpy(float)
        compass = np.radians(pairs["compass_heading_deg"].to_numpy(float))
        source = "compass stage's heading pairs"
    else:
        attitude = _attitude(dive)
        if attitude is None:
            raise NotDrawn("no compass log (nav/attitude.csv) to compare with the SLAM headings")
        t, compass = attitude
        source = "nav/attitude.csv"
    inside = (t >= slam.t_s[0]) & (t <= slam.t_s[-1])
    t, compass = t[inside], compass[inside]
    if t.size < 2:
        raise NotDrawn("the compass log and the SLAM trajectory do not overlap in time")
    s = _thin(t.size)
    t, compass = t[s], compass[s]
    ref = np.interp(t, slam.t_s, np.unwrap(slam.yaw_rad))
    t0 = slam.t_s[0]
    hours = (t - t0) / 3600.0
    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1.3]}
    )
    top.plot(hours, np.degrees(compass) % 360.0, ".", ms=1.5, c="tab:red", label="compass (as logged)")
    top.plot(hours, np.degrees(ref) % 360.0, ".", ms=1.5, c="tab:blue", label="SLAM (true north)")
    top.set_ylabel("heading (deg)")
    top.set_ylim(0, 360)
    top.set_yticks(np.arange(0, 361, 90))
    top.legend(loc="upper right", fontsize="small", markerscale=6)
    diff = np.degrees(angle_diff(ref, compass))
    bottom.plot(hours, diff, ".", ms=1.5, c="0.3")
    loops = loops_file(dive)
    n_loops = 0
    if loops is not None:
        lt = pd.read_csv(loops, usecols=["t_i", "t_j"])
        lt = lt[(lt["t_j"] - lt["t_i"]) > 5.0]  # not the consecutive pairs
        n_loops = len(lt)
        if n_loops:
            sel = lt.iloc[_thin(n_loops, 600)]
            lo, hi = np.nanpercentile(diff, 1), np.nanpercentile(diff, 99)
            ymark = hi + 0.1 * max(hi - lo, 1.0)
            bottom.plot((sel["t_j"] - t0) / 3600.0, np.full(len(sel), ymark), "|", c="tab:green", ms=6)
            bottom.plot([], [], "|", c="tab:green", label=f"loop closures ({n_loops} not consecutive)")
            bottom.legend(loc="lower right", fontsize="small")
    bottom.set_ylabel("SLAM - compass (deg)")
    bottom.set_xlabel("time since the first SLAM pose (h)")
    for ax in (top, bottom):
        ax.grid(True, lw=0.3)
    top.set_title("compass and SLAM headings")
    fig.tight_layout()
    _save(fig, path)
    return f"compass from the {source}; SLAM minus compass RMS {np.sqrt(np.mean(diff**2)):.2f} deg; {n_loops} loop closures"


def _attitude(dive: Path) -> tuple[np.ndarray, np.ndarray] | None:
    from auvnav.dive import AttitudeStream, find_stream_file
    from auvnav.streams import read_stream

    path = find_stream_file(Path(dive), AttitudeStream.FILE)
    if path is None:
        return None
    att = read_stream(AttitudeStream, path)
    return att.t_s, att.heading_rad


# ---------------------------------------------------------------------------------------------
# Fig. 5a/5b: the compass correction and its constant from GPS transits
# ---------------------------------------------------------------------------------------------


def fig5a_correction(dive: Path, path: Path) -> str:
    """The deviation with its Fourier fit (the compass stage's products)."""
    from auvnav.compass.evaluate import TRUE_DEVIATION_FILE, read_true_deviation
    from auvnav.report.compass_figures import CorrectionFigure, plot_correction

    if not P.COMPASS_CORRECTION.path(dive).is_file():
        raise NotDrawn("no compass correction (products/compass: the compass stage did not run)")
    truth = read_true_deviation(dive) if (Path(dive) / TRUE_DEVIATION_FILE).is_file() else None
    figure = CorrectionFigure.from_products(dive)
    plot_correction(figure, path, true_deviation=truth, dpi=DPI)
    return figure.title + ("; dashed: the true deviation" if truth is not None else "")


def plot_transit_constant(summary: dict[str, Any], path: Path) -> str:
    """Each transit leg's GPS course made good minus dead-reckoned course against its heading, and
    the constant term fixed from the used legs (Fig. 5b).

    Parameters
    ----------
    summary : dict
        A compass fit's summary (``products/compass/summary.json`` or a campaign fit's): ``legs``,
        ``a0_deg``, ``constant``.
    path : Path
        PNG to write.
    """
    legs = summary.get("legs") or []
    if not legs:
        raise NotDrawn("no sub-sea transit legs between GPS fixes (the constant cannot be fixed from GPS)")
    used = [leg for leg in legs if leg.get("used")]
    constant = summary.get("constant") or {}
    fig, ax = plt.subplots(figsize=(8, 4))
    for group, style in (
        (used, {"c": "tab:orange", "label": "used"}),
        ([g for g in legs if not g.get("used")], {"c": "0.6", "label": "not used"}),
    ):
        if not group:
            continue
        h = np.array([g["heading_deg"] for g in group]) % 360.0
        err = np.array([g["course_error_deg"] for g in group])
        sig = np.array([g["course_sigma_deg"] for g in group])
        ax.errorbar(h, err, yerr=sig, fmt="o", ms=5, capsize=3, **style)
    a0 = summary.get("a0_deg")
    if a0 is not None:
        sigma = constant.get("sigma_deg")
        ax.axhline(
            a0,
            c="tab:blue",
            lw=1.2,
            label=f"constant a0 = {a0:.3f} deg" + (f" ± {sigma:.3f}" if sigma else ""),
        )
        if sigma:
            ax.axhspan(a0 - 2 * sigma, a0 + 2 * sigma, color="tab:blue", alpha=0.15, lw=0)
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_xlabel("leg's mean compass heading (deg)")
    ax.set_ylabel("GPS course made good - DR course (deg)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_title(
        f"the correction's constant from GPS transits ({len(used)} of {len(legs)} legs used; source {constant.get('source', '?')})"
    )
    fig.tight_layout()
    _save(fig, path)
    reasons = sorted({str(g.get("reason")) for g in legs if not g.get("used") and g.get("reason")})
    return f"{len(used)} legs used" + (f"; not used: {', '.join(reasons)}" if reasons else "")


def fig5b_constant(dive: Path, path: Path) -> str:
    summary = _json(P.COMPASS_SUMMARY, dive)
    if summary is None:
        raise NotDrawn("no compass fit (products/compass: the compass stage did not run)")
    return plot_transit_constant(summary, path)


# ---------------------------------------------------------------------------------------------
# Fig. 6: depth residuals of loop closures
# ---------------------------------------------------------------------------------------------


def fig6_depth(dive: Path, path: Path) -> str:
    from auvnav.report.depth_figures import DepthFigure, plot_depth

    summary = _json(P.DEPTH_SUMMARY, dive)
    if summary is None:
        raise NotDrawn("no depth check (products/depth: the depth stage did not run)")
    plot_depth(DepthFigure.from_products(dive), path, dpi=DPI)
    after = summary.get("residual_rms_after_m")
    return f"{summary['n_loops']} loop closures; residual RMS {summary['residual_rms_before_m']:.3f} m" + (
        "" if after is None else f", {after:.3f} m after the tide"
    )


# ---------------------------------------------------------------------------------------------
# Fig. 8: dead reckoning with and without the correction, against SLAM
# ---------------------------------------------------------------------------------------------


def plot_dr_corrected(dive: Path, correction: Path, path: Path) -> str:
    """Dead reckoning of the dive with the compass as logged and with ``correction`` applied, both
    from the same start, against the SLAM track (Fig. 8)."""
    from auvnav.compass.correction import read_correction
    from auvnav.dive import read_dive
    from auvnav.nav.deadreckon import dead_reckon, start_position
    from auvnav.nav.inputs import nav_inputs

    slam = _trajectory(dive, P.SLAM_TRAJECTORY, NO_SLAM)
    data = read_dive(dive)
    raw = nav_inputs(data)
    fixed = nav_inputs(data, read_correction(correction))
    start = start_position(raw, raw.displacement_ned_m())
    tracks = [
        ("compass as logged", dead_reckon(raw, start), "tab:red"),
        ("corrected", dead_reckon(fixed, start), "tab:green"),
    ]
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(
        slam.p_ned_m[_thin(len(slam)), 1],
        slam.p_ned_m[_thin(len(slam)), 0],
        c="tab:blue",
        lw=1.2,
        label="SLAM",
    )
    ends = []
    for label, traj, colour in tracks:
        s = _thin(len(traj))
        ax.plot(traj.p_ned_m[s, 1], traj.p_ned_m[s, 0], c=colour, lw=0.8, label=f"DR, {label}")
        at = np.clip(np.searchsorted(traj.t_s, slam.t_s[-1]), 0, len(traj) - 1)
        ends.append(float(np.linalg.norm(traj.p_ned_m[at, :2] - slam.p_ned_m[-1, :2])))
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_title(f"dead reckoning with and without the correction ({Path(correction).name})")
    fig.tight_layout()
    _save(fig, path)
    return f"at SLAM's last pose, DR is {ends[0]:.2f} m away with the compass as logged, {ends[1]:.2f} m corrected"


def fig8_corrected(dive: Path, path: Path, correction: Path | None = None) -> str:
    if correction is None:
        correction = P.COMPASS_CORRECTION.path(dive)
        if not correction.is_file():
            raise NotDrawn("no compass correction to apply (products/compass: the compass stage did not run)")
    if not P.SLAM_TRAJECTORY.path(dive).is_file():
        raise NotDrawn(NO_SLAM)
    return plot_dr_corrected(dive, correction, path)


# ---------------------------------------------------------------------------------------------
# Fig. 9: GPS innovations
# ---------------------------------------------------------------------------------------------


def fig9_innovations(dive: Path, path: Path) -> str:
    """Every fix's innovation in north and east with its 2-sigma bound, against the fix's number (fixes
    come in bursts at the surface: the dives between them are marked with their length); rejected
    fixes marked."""
    file = P.NAV_INNOVATIONS.path(dive)
    if not file.is_file():
        raise NotDrawn(NO_NAV)
    inn = pd.read_csv(file)
    if inn.empty:
        raise NotDrawn("no GPS or USBL fixes: the navigation had no innovations")
    t = inn["t"].to_numpy(float)
    k = np.arange(len(inn), dtype=float)
    gap = np.flatnonzero(np.diff(t) > 120.0)  # submerged between these fixes
    x = k.copy()
    accepted = inn["accepted"].to_numpy(bool)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    inside = []
    for ax, axis in zip(axes, ("north", "east"), strict=True):
        value = inn[f"innovation_{axis}_m"].to_numpy(float)
        sigma = inn[f"sigma_{axis}_m"].to_numpy(float)
        bound = np.where(sigma < 100.0, 2.0 * sigma, np.nan)  # the first fix's prior is not a bound
        xb, yb = x.copy(), bound.copy()
        yb[gap] = np.nan  # no band across a dive
        ax.fill_between(xb, -yb, yb, color="tab:blue", alpha=0.25, lw=0, label="2-sigma")
        for sensor, marker in (("gps", "o"), ("usbl", "s")):
            m = (inn["sensor"] == sensor).to_numpy()
            if not m.any():
                continue
            ax.plot(
                x[m & accepted],
                value[m & accepted],
                marker,
                ms=2.5,
                c="k",
                ls="",
                label=f"{sensor.upper()} innovation",
            )
            if (m & ~accepted).any():
                ax.plot(
                    x[m & ~accepted],
                    value[m & ~accepted],
                    "x",
                    ms=5,
                    c="tab:red",
                    ls="",
                    label=f"{sensor.upper()} rejected",
                )
        for g in gap:
            ax.axvline(g + 0.5, c="0.4", ls="--", lw=0.8)
        ok = np.isfinite(bound)
        inside.append(np.abs(value[ok]) <= bound[ok])
        ax.set_ylabel(f"{axis} innovation (m)")
        ax.grid(True, lw=0.3)
        lim = np.nanpercentile(np.abs(np.concatenate([value[ok], bound[ok]])), 99) * 1.3 if ok.any() else 1.0
        ax.set_ylim(-lim, lim)
    for g in gap:
        axes[0].annotate(
            f"submerged {(t[g + 1] - t[g]) / 3600.0:.1f} h",
            (g + 0.5, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(3, -12),
            textcoords="offset points",
            fontsize="small",
            color="0.3",
        )
    axes[0].legend(loc="lower right", fontsize="small", ncol=3)
    axes[1].set_xlabel("fix number")
    both = np.concatenate(inside) if inside else np.zeros(0, bool)
    share = float(np.mean(both)) if both.size else float("nan")
    axes[0].set_title(f"fix innovations with 2-sigma bounds: {100 * share:.0f}% inside")
    fig.tight_layout()
    _save(fig, path)
    return (
        f"{len(inn)} fixes ({int(accepted.sum())} accepted) in {len(gap) + 1} surface periods; {100 * share:.1f}% "
        "of the innovations inside 2 sigma"
    )


# ---------------------------------------------------------------------------------------------
# Fig. 10 and 11: the reconstruction and its false relief; the coverage map
# ---------------------------------------------------------------------------------------------

NO_RECON = "no reconstruction (products/recon: the recon stage did not run)"


def fig10_reconstruction(dive: Path, path: Path) -> str:
    """A rendered view of the decimated mesh (left) and the shaded DEM (right)."""
    from matplotlib.colors import LightSource

    from auvnav.dive import read_dive_info
    from auvnav.report.mesh import REPORT_TRIANGLES, read_decimated_mesh
    from auvnav.report.rasters import read_raster_preview

    dem_path, mesh_path = P.RECON_DEM.path(dive), P.RECON_MESH.path(dive)
    if not dem_path.is_file() and not mesh_path.is_file():
        raise NotDrawn(NO_RECON)
    fig = plt.figure(figsize=(11, 5))
    notes = []
    if mesh_path.is_file():
        mesh = read_decimated_mesh(mesh_path, REPORT_TRIANGLES)
        ax = fig.add_subplot(1, 2, 1, projection="3d")
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        tri = mesh.vertices_m[mesh.triangles]
        z = mesh.vertices_m[:, 2]
        # elevation (robust range), shaded by the faces' slope towards a light in the north-west: the
        # texture's grey is in the 3D view and the orthophoto; here the relief is what matters
        lo_z, hi_z = np.percentile(z, [2, 98])
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        normal *= np.sign(normal[:, 2:3] + 1e-12)
        light = np.array([-0.5, 0.5, 0.707]) / np.linalg.norm([-0.5, 0.5, 0.707])
        shade = (0.35 + 0.65 * np.clip(normal @ light, 0.0, 1.0))[:, None]
        level = np.clip((tri[:, :, 2].mean(axis=1) - lo_z) / max(hi_z - lo_z, 1e-6), 0.0, 1.0)
        colour = plt.cm.terrain(0.15 + 0.7 * level)[:, :3] * shade
        ax.add_collection3d(Poly3DCollection(tri, facecolors=colour, linewidths=0))
        lo, hi = mesh.vertices_m.min(axis=0), mesh.vertices_m.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo_z - 0.5, lo_z - 0.5 + max(hi[0] - lo[0], hi[1] - lo[1]) / 3)
        ax.view_init(elev=45, azim=-60)
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_zlabel("up (m)")
        ax.set_title(f"mesh ({len(mesh.triangles):,} of {mesh.full_triangles:,} triangles)")
        notes.append(f"mesh of {mesh.full_triangles:,} triangles drawn decimated to {len(mesh.triangles):,}")
    else:
        fig.text(0.25, 0.5, "no mesh (products/recon/mesh.ply)", ha="center")
    if dem_path.is_file():
        dem = read_raster_preview(dem_path, read_dive_info(dive).origin, 800)
        ax = fig.add_subplot(1, 2, 2)
        z = np.ma.masked_invalid(dem.band)
        cell = dem.cell_m
        vmin, vmax = np.nanpercentile(dem.band, [2, 98]) if z.count() else (0.0, 1.0)
        shaded = LightSource(azdeg=315, altdeg=45).shade(
            z.filled(np.nanmean(z) if z.count() else 0.0),
            vmin=vmin,
            vmax=vmax,
            cmap=plt.cm.terrain,
            vert_exag=3.0,
            dx=cell,
            dy=cell,
            blend_mode="soft",
        )
        shaded[np.ma.getmaskarray(z)] = (1, 1, 1, 1)
        ax.imshow(shaded, extent=dem.extent_local_en(), origin="upper")
        scale = plt.cm.ScalarMappable(norm=matplotlib.colors.Normalize(vmin, vmax), cmap=plt.cm.terrain)
        fig.colorbar(scale, ax=ax, label="elevation (m)", shrink=0.8)
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_title(
            f"DEM, shaded ({dem.full_shape[1]}x{dem.full_shape[0]} cells of {100 * dem.full_cell_m:.0f} cm)"
        )
        notes.append(f"DEM elevation {np.nanmin(dem.band):.2f} to {np.nanmax(dem.band):.2f} m")
    else:
        fig.text(0.75, 0.5, "no DEM (products/recon/dem.tif)", ha="center")
    fig.tight_layout()
    _save(fig, path)
    return "; ".join(notes)


def fig11_relief(dive: Path, path: Path) -> str:
    """False relief between far-apart visits of the same patch: the step with pressure depth before
    and after the tide correction, against the time between the visits."""
    file = P.RECON_RELIEF.path(dive)
    if not file.is_file():
        raise NotDrawn(NO_RECON)
    relief = pd.read_csv(file)
    if relief.empty:
        raise NotDrawn("no patch was seen twice far enough apart in time (relief.csv is empty)")
    summary = _json(P.RECON_SUMMARY, dive) or {}
    step = float((summary.get("fusion") or {}).get("relief_step_m") or 0.1)
    hours = relief["dt_s"].to_numpy(float) / 3600.0
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(hours, 100 * relief["step_before_m"], "o", ms=4, c="tab:red", label="before the tide correction")
    if relief["step_after_m"].notna().any():
        ax.plot(
            hours, 100 * relief["step_after_m"], "o", ms=4, c="tab:green", label="after the tide correction"
        )
    if "tide_change_m" in relief and relief["tide_change_m"].notna().any():
        ax.plot(hours, -100 * relief["tide_change_m"], "k_", ms=8, label="minus the tide change")
    for sign in (-1, 1):
        ax.axhline(100 * sign * step, c="tab:red", ls="--", lw=0.6)
    ax.axhline(0, c="0.3", lw=0.5)
    ax.set_xlabel("time between the two visits (h)")
    ax.set_ylabel("false relief step (cm)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize="small")
    before = np.sqrt(np.nanmean(relief["step_before_m"] ** 2))
    after = np.sqrt(np.nanmean(relief["step_after_m"] ** 2)) if relief["step_after_m"].notna().any() else None
    ax.set_title(
        f"false relief on {len(relief)} revisits: {100 * before:.1f} cm RMS before"
        + ("" if after is None else f", {100 * after:.1f} cm after the tide")
    )
    fig.tight_layout()
    _save(fig, path)
    return f"{len(relief)} revisits; steps beyond ±{100 * step:.0f} cm are false relief"


def coverage_map(dive: Path, path: Path) -> str:
    """The coverage stage's own map (images per cell), copied: it is already a figure."""
    png = P.COVERAGE_PNG.path(dive)
    if not png.is_file():
        raise NotDrawn("no coverage analysis (products/coverage: the coverage stage did not run)")
    atomic_write(Path(path), lambda p: p.write_bytes(png.read_bytes()))
    summary = _json(P.COVERAGE_SUMMARY, dive) or {}
    pct = summary.get("coverage_pct")
    gaps = (summary.get("gaps") or {}).get("area_m2")
    parts = []
    if pct is not None:
        parts.append(f"coverage {pct:.1f}%")
    if gaps is not None:
        parts.append(f"gaps {gaps:.1f} m²")
    return ", ".join(parts) or "images per map cell"


# ---------------------------------------------------------------------------------------------
# All of them
# ---------------------------------------------------------------------------------------------

#: key, file, title, function(dive, path) -> caption
FIGURES: tuple[tuple[str, str, str, Callable[[Path, Path], str]], ...] = (
    ("fig2", "fig2_paths.png", "Fig. 2: dead reckoning, filter and SLAM tracks", fig2_paths),
    (
        "fig4",
        "fig4_headings.png",
        "Fig. 4: compass against SLAM headings, with the loop closures",
        fig4_headings,
    ),
    ("fig5a", "fig5_compass.png", "Fig. 5a: compass deviation and its Fourier fit", fig5a_correction),
    ("fig5b", "fig5b_constant.png", "Fig. 5b: the constant term from GPS transits", fig5b_constant),
    ("fig6", "fig6_depth.png", "Fig. 6: depth residuals of the loop closures", fig6_depth),
    (
        "fig8",
        "fig8_corrected.png",
        "Fig. 8: dead reckoning with and without the correction, against SLAM",
        fig8_corrected,
    ),
    ("fig9", "fig9_innovations.png", "Fig. 9: GPS innovations with 2-sigma bounds", fig9_innovations),
    ("coverage", "coverage.png", "Coverage map: images per cell", coverage_map),
    (
        "fig10",
        "fig10_reconstruction.png",
        "Fig. 10: the reconstruction (mesh and shaded DEM)",
        fig10_reconstruction,
    ),
    ("fig11", "fig11_relief.png", "Fig. 11: false relief with and without the tide", fig11_relief),
)


#: The stage whose products each figure needs most (its record says why it did not run).
STAGE_OF = {
    "fig2": "nav",
    "fig4": "slam",
    "fig5a": "compass",
    "fig5b": "compass",
    "fig6": "depth",
    "fig8": "compass",
    "fig9": "nav",
    "coverage": "coverage",
    "fig10": "recon",
    "fig11": "recon",
}


def stage_reason(dive: Path, stage: str) -> str | None:
    """Why a stage did not give products, from its record (skipped or failed, with its reason)."""
    record = P.read_record(dive, stage)
    if record is None or record.get("status", "ran") == "ran" or not record.get("reason"):
        return None
    return f"the {stage} stage was {record['status']}: {record['reason']}"


def draw_figures(dive: Path, folder: Path) -> list[Panel]:
    """Every figure of :data:`FIGURES` the dive's products allow, into ``folder``; a panel for each
    (drawn, or why not: the stage's own reason when it was skipped). A figure that fails on products
    it should read is reported, not raised."""
    panels = []
    for key, name, title, draw in FIGURES:
        try:
            caption = draw(Path(dive), Path(folder) / name)
            panels.append(Panel(key, title, file=name, caption=caption))
        except NotDrawn as why:
            reason = stage_reason(Path(dive), STAGE_OF[key])
            panels.append(Panel(key, title, why=reason or str(why)))
        except (
            AuvnavError,
            OSError,
            ValueError,
            KeyError,
            IndexError,
        ) as err:  # a product that does not read
            log.warning("%s: %s not drawn: %s", dive, key, err)
            panels.append(
                Panel(key, title, why=f"could not be drawn from the products: {type(err).__name__}: {err}")
            )
    return panels
