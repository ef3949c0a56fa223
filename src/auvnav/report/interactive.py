"""The report's interactive views (plotly): a map of the dive and a 3D view of its mesh.

The map is a plotly figure in the dive's local metres (east right, north up, equal scales): the
tracks (dead reckoning, filter, SLAM, the truth of a simulated dive), the GPS and USBL fixes and the
loop closures are traces a click on the legend turns on and off; the orthophoto, when the
reconstruction made one, is a layout image under them. It pans and zooms with no tiles and no
network. The 3D view is a ``mesh3d`` of the reconstruction's mesh decimated to a few tens of
thousands of triangles (:mod:`auvnav.report.mesh`).

Each function returns the figure as JSON text for ``Plotly.newPlot`` (arrays as base64 typed arrays),
or raises :class:`~auvnav.report.paper_figures.NotDrawn` with the reason.
"""

from __future__ import annotations

import base64
import io
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvnav import products as P
from auvnav.dive import DiveInfo, GpsStream, UsblStream, find_stream_file, read_dive_info
from auvnav.frames import geodetic2ned
from auvnav.report.paper_figures import NO_NAV, NO_RECON, TRUTH_TRAJECTORY, NotDrawn, loops_file
from auvnav.streams import read_stream
from auvnav.trajectory import read_trajectory

#: At most this many points per track and this many loop-closure segments are put on the map.
MAP_TRACK_POINTS = 3000
MAP_LOOPS = 1500
#: The orthophoto on the map: at most this many pixels on its longer side.
MAP_MOSAIC_PX = 1200

COLOURS = {"dr": "#d62728", "filter": "#ff7f0e", "slam": "#1f77b4", "truth": "#000000"}


def _thin(a: np.ndarray, most: int) -> np.ndarray:
    return a[:: max(1, int(np.ceil(len(a) / most)))]


def _fixes(dive: Path, info: DiveInfo) -> list[dict[str, Any]]:
    traces = []
    for cls, name, symbol in ((GpsStream, "GPS fixes", "circle"), (UsblStream, "USBL fixes", "square")):
        path = find_stream_file(dive, cls.FILE)
        if path is None:
            continue
        fixes = read_stream(cls, path)
        ned = geodetic2ned(
            fixes.latitude_rad,
            fixes.longitude_rad,
            np.full(len(fixes.t_s), info.origin.height_m),
            info.origin,
        )
        ned = np.asarray(ned, dtype=float)
        keep = slice(None, None, max(1, int(np.ceil(len(ned) / MAP_TRACK_POINTS))))
        traces.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": f"{name} ({len(ned)})",
                "x": ned[keep, 1],
                "y": ned[keep, 0],
                "marker": {"size": 5, "symbol": symbol, "color": "#2ca02c", "line": {"width": 0}},
            }
        )
    return traces


def _loops(dive: Path, slam_t: np.ndarray, slam_ne: np.ndarray) -> dict[str, Any] | None:
    path = loops_file(dive)
    if path is None:
        return None
    loops = pd.read_csv(path, usecols=["t_i", "t_j"])
    loops = loops[(loops["t_j"] - loops["t_i"]) > 5.0]  # not the consecutive pairs
    if loops.empty:
        return None
    n = len(loops)
    loops = loops.iloc[:: max(1, int(np.ceil(n / MAP_LOOPS)))]
    a = np.column_stack([np.interp(loops["t_i"], slam_t, slam_ne[:, k]) for k in (0, 1)])
    b = np.column_stack([np.interp(loops["t_j"], slam_t, slam_ne[:, k]) for k in (0, 1)])
    x = np.column_stack([a[:, 1], b[:, 1], np.full(len(a), np.nan)]).ravel()
    y = np.column_stack([a[:, 0], b[:, 0], np.full(len(a), np.nan)]).ravel()
    shown = "" if len(loops) == n else f", {len(loops)} shown"
    return {
        "type": "scatter",
        "mode": "lines",
        "name": f"loop closures ({n}{shown})",
        "x": x,
        "y": y,
        "line": {"width": 0.5, "color": "rgba(44,160,44,0.5)"},
        "visible": "legendonly",
        "hoverinfo": "skip",
    }


def _mosaic(dive: Path, info: DiveInfo) -> dict[str, Any] | None:
    from PIL import Image

    from auvnav.report.rasters import read_raster_preview

    path = P.RECON_MOSAIC.path(dive)
    if not path.is_file():
        return None
    preview = read_raster_preview(path, info.origin, MAP_MOSAIC_PX)
    grey = preview.band
    alpha = np.where(np.isfinite(grey) & (grey > 0), 255, 0).astype(np.uint8)
    grey = np.nan_to_num(grey, nan=0.0).clip(0, 255).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(np.dstack([grey, grey, grey, alpha]), "RGBA").save(buffer, format="PNG", optimize=True)
    west, east, south, north = preview.extent_local_en()
    return {
        "source": "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii"),
        "xref": "x",
        "yref": "y",
        "x": west,
        "y": north,
        "sizex": east - west,
        "sizey": north - south,
        "sizing": "stretch",
        "layer": "below",
        "opacity": 1.0,
    }


def map_figure(dive: Path) -> tuple[str, str]:
    """The dive's map as plotly JSON, and a caption.

    Raises
    ------
    NotDrawn
        The dive has no navigation products.
    """
    import plotly.graph_objects as go
    import plotly.io as pio

    dive = Path(dive)
    if not P.NAV_DR.path(dive).is_file():
        raise NotDrawn(NO_NAV)
    info = read_dive_info(dive)
    traces: list[dict[str, Any]] = []
    names = []
    slam = None
    for key, product, label in (
        ("truth", None, "truth"),
        ("dr", P.NAV_DR, "dead reckoning"),
        ("filter", P.NAV_FILTER, "filter (GPS)"),
        ("slam", P.SLAM_TRAJECTORY, "SLAM"),
    ):
        path = dive / TRUTH_TRAJECTORY if product is None else product.path(dive)
        if not path.is_file():
            continue
        traj = read_trajectory(path)
        if key == "slam":
            slam = traj
        p = _thin(traj.p_ned_m, MAP_TRACK_POINTS)
        t = _thin(traj.t_s, MAP_TRACK_POINTS)
        traces.append(
            {
                "type": "scatter",
                "mode": "lines",
                "name": label,
                "x": p[:, 1],
                "y": p[:, 0],
                "customdata": (t - info.start_time_s) / 60.0,
                "hovertemplate": f"{label}<br>east %{{x:.2f}} m<br>north %{{y:.2f}} m<br>%{{customdata:.1f}} min<extra></extra>",
                "line": {
                    "width": 1.0 if key != "truth" else 0.8,
                    "color": COLOURS[key],
                    "dash": "dash" if key == "truth" else "solid",
                },
            }
        )
        names.append(label)
    traces += _fixes(dive, info)
    if slam is not None:
        loops = _loops(dive, slam.t_s, slam.p_ned_m[:, :2])
        if loops is not None:
            traces.append(loops)
    images = []
    mosaic = _mosaic(dive, info)
    if mosaic is not None:
        images.append(mosaic)
    fig = go.Figure(
        data=traces,
        layout={
            "xaxis": {"title": {"text": "east (m)"}, "zeroline": False},
            "yaxis": {"title": {"text": "north (m)"}, "scaleanchor": "x", "scaleratio": 1, "zeroline": False},
            "images": images,
            "height": 620,
            "margin": {"l": 60, "r": 20, "t": 30, "b": 50},
            "legend": {"itemclick": "toggle", "bgcolor": "rgba(255,255,255,0.7)"},
            "dragmode": "pan",
            "hovermode": "closest",
            "template": "plotly_white",
            "uirevision": "map",
        },
    )
    caption = f"tracks: {', '.join(names)}; {len(traces) - len(names)} other layers" + (
        "; the orthophoto underneath" if mosaic is not None else ""
    )
    return pio.to_json(fig, validate=False), caption


def mesh_figure(dive: Path) -> tuple[str, str]:
    """The decimated mesh as a plotly ``mesh3d`` (JSON) and a caption; NotDrawn without a mesh."""
    import plotly.graph_objects as go
    import plotly.io as pio

    from auvnav.report.mesh import REPORT_TRIANGLES, read_decimated_mesh

    path = P.RECON_MESH.path(dive)
    if not path.is_file():
        raise NotDrawn(NO_RECON)
    mesh = read_decimated_mesh(path, REPORT_TRIANGLES)
    v, f = mesh.vertices_m.astype(np.float32), mesh.triangles.astype(np.int32)
    trace: dict[str, Any] = {
        "type": "mesh3d",
        "x": v[:, 0],
        "y": v[:, 1],
        "z": v[:, 2],
        "i": f[:, 0],
        "j": f[:, 1],
        "k": f[:, 2],
        "flatshading": False,
        "lighting": {"ambient": 0.6, "diffuse": 0.6, "specular": 0.05},
        "hoverinfo": "skip",
        "name": "mesh",
    }
    if mesh.has_colour:
        rgb = (255 * mesh.colours.clip(0, 1)).astype(np.uint8)
        trace["vertexcolor"] = [f"rgb({r},{g},{b})" for r, g, b in rgb]
    else:
        trace["intensity"] = v[:, 2]
        trace["colorscale"] = "Earth"
    span = np.ptp(v, axis=0)
    fig = go.Figure(
        data=[trace],
        layout={
            "scene": {
                "aspectmode": "manual",
                "aspectratio": {
                    "x": 1.0,
                    "y": float(span[1] / max(span[0], 1e-6)),
                    "z": float(max(span[2] / max(span[0], 1e-6), 0.15)),
                },
                "xaxis": {"title": {"text": "east (m)"}},
                "yaxis": {"title": {"text": "north (m)"}},
                "zaxis": {"title": {"text": "up (m)"}},
            },
            "height": 560,
            "margin": {"l": 0, "r": 0, "t": 10, "b": 0},
        },
    )
    caption = f"{len(f):,} of the mesh's {mesh.full_triangles:,} triangles; drag to turn, scroll to zoom"
    return pio.to_json(fig, validate=False), caption
