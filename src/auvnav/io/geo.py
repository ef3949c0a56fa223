"""GeoJSON and KML of a dive's track and loop closures (WGS84), for QGIS and Google Earth.

Both hold the trajectory (SLAM's, else the filter's, else dead reckoning) as one line, and each loop
closure between non-consecutive stereo pairs (a revisit) as a line from where the first image was
taken to where the second was, both placed on that trajectory. GeoJSON (RFC 7946) positions are
``[longitude, latitude, height]`` with height = -depth, metres; KML lines are clamped to the ground
(Google Earth draws them on the sea surface).
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import numpy as np

from auvnav.dive import read_dive_info
from auvnav.io.tracks import geodetic, nonconsecutive, read_loop_closures, read_track
from auvnav.streams import atomic_write
from auvnav.trajectory import Trajectory


def _iso(t: float) -> str:
    return (
        dt.datetime.fromtimestamp(t, dt.timezone.utc)
        .isoformat(timespec="milliseconds")
        .replace("+00:00", "Z")
    )


def _content(
    dive: Path, source: str
) -> tuple[Any, str, np.ndarray, np.ndarray, Trajectory, list[dict[str, Any]]]:
    info = read_dive_info(dive)
    track, name = read_track(dive, source)
    lat, lon = geodetic(track, info.origin)
    loops = read_loop_closures(dive)
    found: list[dict[str, Any]] = []
    if loops is not None:
        keep = nonconsecutive(loops)
        ti, tj = np.asarray(loops.t_i_s)[keep], np.asarray(loops.t_j_s)[keep]
        inside = (ti >= track.t_s[0]) & (ti <= track.t_s[-1]) & (tj >= track.t_s[0]) & (tj <= track.t_s[-1])
        if inside.any():
            a = track.interpolate(ti[inside])
            b = track.interpolate(tj[inside])
            la, loa = geodetic(a, info.origin)
            lb, lob = geodetic(b, info.origin)
            ii, jj = np.asarray(loops.i)[keep][inside], np.asarray(loops.j)[keep][inside]
            inl = np.asarray(loops.inliers)[keep][inside]
            for k in range(len(la)):
                found.append(
                    {
                        "i": int(ii[k]),
                        "j": int(jj[k]),
                        "t_i": float(ti[inside][k]),
                        "t_j": float(tj[inside][k]),
                        "inliers": int(inl[k]),
                        "lonlat": [[float(loa[k]), float(la[k])], [float(lob[k]), float(lb[k])]],
                    }
                )
    return info, name, lat, lon, track, found


def export_geojson(dive: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write the track and loop closures as a GeoJSON FeatureCollection."""
    info, source, lat, lon, track, loops = _content(dive, options.source)
    coords = [
        [round(float(x), 9), round(float(y), 9), round(float(-z), 4)]
        for x, y, z in zip(lon, lat, track.p_ned_m[:, 2], strict=True)
    ]
    features: list[dict[str, Any]] = [
        {
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": coords},
            "properties": {
                "kind": "track",
                "dive": info.name,
                "source": source,
                "start": _iso(float(track.t_s[0])),
                "end": _iso(float(track.t_s[-1])),
                "points": len(coords),
            },
        }
    ]
    for loop in loops:
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": loop["lonlat"]},
                "properties": {"kind": "loop", **{k: v for k, v in loop.items() if k != "lonlat"}},
            }
        )
    doc = {"type": "FeatureCollection", "features": features}
    text = json.dumps(doc, separators=(",", ":")) + "\n"
    atomic_write(out, lambda p: p.write_text(text, encoding="utf-8"))
    return {"trajectory": source, "points": len(coords), "loops": len(loops)}


def export_kml(dive: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write the track and loop closures as KML 2.2."""
    info, source, lat, lon, track, loops = _content(dive, options.source)
    track_coords = " ".join(f"{x:.9f},{y:.9f}" for x, y in zip(lon, lat, strict=True))
    parts = [
        '<?xml version="1.0" encoding="UTF-8"?>\n<kml xmlns="http://www.opengis.net/kml/2.2">\n<Document>\n',
        f"<name>{escape(info.name)}</name>\n",
        '<Style id="track"><LineStyle><color>ff0000ff</color><width>2</width></LineStyle></Style>\n',
        '<Style id="loop"><LineStyle><color>ff00ffff</color><width>1</width></LineStyle></Style>\n',
        f"<Placemark><name>{escape(source)} track</name><styleUrl>#track</styleUrl>"
        f"<TimeSpan><begin>{_iso(float(track.t_s[0]))}</begin><end>{_iso(float(track.t_s[-1]))}</end></TimeSpan>"
        f"<LineString><tessellate>1</tessellate><altitudeMode>clampToGround</altitudeMode>"
        f"<coordinates>{track_coords}</coordinates></LineString></Placemark>\n",
        f"<Folder><name>loop closures ({len(loops)})</name>\n",
    ]
    for loop in loops:
        (x0, y0), (x1, y1) = loop["lonlat"]
        parts.append(
            f"<Placemark><name>{loop['i']}-{loop['j']}</name><styleUrl>#loop</styleUrl>"
            f"<LineString><altitudeMode>clampToGround</altitudeMode>"
            f"<coordinates>{x0:.9f},{y0:.9f} {x1:.9f},{y1:.9f}</coordinates></LineString></Placemark>\n"
        )
    parts.append("</Folder>\n</Document>\n</kml>\n")
    text = "".join(parts)
    atomic_write(out, lambda p: p.write_text(text, encoding="utf-8"))
    return {"trajectory": source, "points": len(lat), "loops": len(loops)}
