"""The bad-input catalogue: every named corruption of every file a dive, a mission or a command reads
gives exit code 1, one line on stderr naming the file, no traceback, bounded memory, and leaves
``products/`` as it was.

Each case corrupts a copy of the valid samples (``tests/bad_input.py``: a dive with products from
an earlier run, and every other kind of file), runs one command, and checks:

- exit code 1, and stderr is exactly one line: ``auvnav: error: ...`` naming the file (a
  traceback would be more lines);
- peak memory under :data:`MAX_MEMORY_MB`: for the cases run in this process, the process's peak
  resident set during the command (reset before it) less its resident set before; for the heavy ones (an alias bomb,
  a 200 MB field, deep nesting, a 17 MB YAML file, far waypoints), the peak resident set
  (``VmHWM``) of a fresh process;
- nothing changed under ``DIVE/products/`` (the lock file and the file-hash cache of the pipeline
  excepted), and no output of the command written.

``test_no_read_outside_the_dive_without_being_said`` links files outside the dive in every way a
dive names files, and checks with an audit hook that nothing outside is opened unless
``--allow-outside`` is given, and then that every file read outside is said.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import io
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import yaml

from auvnav.cli import main

#: Peak memory a command may use on any bad input, MB.
MAX_MEMORY_MB = 300
#: Files under products/ that a failed command may touch: the pipeline's lock and its hash cache.
BOOKKEEPING = {".lock", "cache/hashes.json"}


def _load_samples_module() -> ModuleType:
    """``tests/bad_input.py``, once per process (test files cannot import each other by name)."""
    name = "auvnav_tests_bad_input"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("bad_input.py"))
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


bad_input = _load_samples_module()
START = bad_input.START_S

# ---------------------------------------------------------------------------------------------
# Corruptions (each takes the work folder: the dive is w/dive, the other samples beside it)
# ---------------------------------------------------------------------------------------------

Corrupt = Callable[[Path], None]


def replace(rel: str, old: str, new: str) -> Corrupt:
    def f(w: Path) -> None:
        text = (w / rel).read_text(encoding="utf-8")
        assert old in text, f"{rel}: {old!r} not found"
        (w / rel).write_text(text.replace(old, new, 1), encoding="utf-8")

    return f


def put(rel: str, content: str | bytes) -> Corrupt:
    def f(w: Path) -> None:
        (w / rel).parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            (w / rel).write_bytes(content)
        else:
            (w / rel).write_text(content, encoding="utf-8")

    return f


def append(rel: str, text: str) -> Corrupt:
    def f(w: Path) -> None:
        with open(w / rel, "a", encoding="utf-8") as fh:
            fh.write(text)

    return f


def edit_yaml(rel: str, change: Callable[[dict], None]) -> Corrupt:
    def f(w: Path) -> None:
        data = yaml.safe_load((w / rel).read_text(encoding="utf-8"))
        change(data)
        (w / rel).write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")

    return f


def set_key(rel: str, path: str, value: object) -> Corrupt:
    def change(data: dict) -> None:
        *parents, last = path.split(".")
        for p in parents:
            data = data[p]
        data[last] = value

    return edit_yaml(rel, change)


def del_key(rel: str, path: str) -> Corrupt:
    def change(data: dict) -> None:
        *parents, last = path.split(".")
        for p in parents:
            data = data[p]
        del data[last]

    return edit_yaml(rel, change)


def edit_lines(rel: str, change: Callable[[list[str]], list[str]]) -> Corrupt:
    def f(w: Path) -> None:
        lines = (w / rel).read_text(encoding="utf-8").splitlines()
        (w / rel).write_text("\n".join(change(lines)) + "\n", encoding="utf-8")

    return f


def cell(rel: str, row: int, column: str, value: str) -> Corrupt:
    def change(lines: list[str]) -> list[str]:
        header = lines[0].split(",")
        cells = lines[row].split(",")
        cells[header.index(column)] = value
        lines[row] = ",".join(cells)
        return lines

    return edit_lines(rel, change)


def column(rel: str, name: str, fn: Callable[[str], str]) -> Corrupt:
    def change(lines: list[str]) -> list[str]:
        k = lines[0].split(",").index(name)
        out = [lines[0]]
        for line in lines[1:]:
            cells = line.split(",")
            cells[k] = fn(cells[k])
            out.append(",".join(cells))
        return out

    return edit_lines(rel, change)


def shift(rel: str, seconds: float) -> Corrupt:
    return column(rel, "t", lambda v: repr(float(v) + seconds))


def rename_column(rel: str, old: str, new: str) -> Corrupt:
    return edit_lines(rel, lambda lines: [lines[0].replace(old, new, 1), *lines[1:]])


def remove(rel: str) -> Corrupt:
    def f(w: Path) -> None:
        path = w / rel
        shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()

    return f


def fifo(rel: str) -> Corrupt:
    def f(w: Path) -> None:
        (w / rel).unlink(missing_ok=True)
        os.mkfifo(w / rel)

    return f


def folder(rel: str) -> Corrupt:
    def f(w: Path) -> None:
        (w / rel).unlink(missing_ok=True)
        (w / rel).mkdir()

    return f


def link(rel: str, target: str) -> Corrupt:
    """``rel`` made a symbolic link to ``target`` (relative to the work folder: outside the dive)."""

    def f(w: Path) -> None:
        path, goal = w / rel, w / target
        if not goal.exists():
            goal.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(path, goal) if path.is_file() else goal.write_text("x\n")
        path.unlink(missing_ok=True)
        path.symlink_to(goal)

    return f


def both(*corruptions: Corrupt) -> Corrupt:
    def f(w: Path) -> None:
        for c in corruptions:
            c(w)

    return f


def also_parquet(rel_csv: str) -> Corrupt:
    """The CSV stream also as Parquet: two files for one stream."""

    def f(w: Path) -> None:
        import pandas as pd

        pd.read_csv(w / rel_csv).to_parquet(w / rel_csv.replace(".csv", ".parquet"), index=False)

    return f


def parquet_copy(rel_csv: str, edit: Callable | None = None) -> Corrupt:
    """The CSV stream as Parquet (the CSV removed), edited as a frame."""

    def f(w: Path) -> None:
        import pandas as pd

        frame = pd.read_csv(w / rel_csv)
        frame = edit(frame) if edit else frame
        frame.to_parquet(w / rel_csv.replace(".csv", ".parquet"), index=False)
        (w / rel_csv).unlink()

    return f


def image(rel: str, width: int, height: int) -> Corrupt:
    def f(w: Path) -> None:
        import cv2

        cv2.imwrite(str(w / rel), np.zeros((height, width), np.uint8))

    return f


def big_field(rel: str, column_name: str, megabytes: int) -> Corrupt:
    """One field of ``megabytes`` MB, written in pieces (the test never holds it)."""

    def f(w: Path) -> None:
        lines = (w / rel).read_text(encoding="utf-8").splitlines()
        header = lines[0].split(",")
        cells = lines[1].split(",")
        k = header.index(column_name)
        with open(w / rel, "w", encoding="utf-8") as fh:
            fh.write(lines[0] + "\n" + ",".join(cells[:k]) + ("," if k else ""))
            for _ in range(megabytes):
                fh.write("9" * 2**20)
            fh.write(("," if k < len(cells) - 1 else "") + ",".join(cells[k + 1 :]) + "\n")
            fh.write("\n".join(lines[2:]) + "\n")

    return f


ALIAS_BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{','.join([f'*{chr(97 + i)}'] * 9)}]\n" for i in range(8)
)
DEEP_LISTS = "[" * 100_000 + "]" * 100_000
DEEP_MAPS = "a: " + "{a: " * 100_000 + "1" + "}" * 100_000
NESTED_40 = "a: " + "[" * 40 + "]" * 40 + "\n"

# ---------------------------------------------------------------------------------------------
# Commands
# ---------------------------------------------------------------------------------------------

VALIDATE = ("validate", "{d}")
NAVIGATE = ("navigate", "{d}")
PROCESS = ("process", "-q", "{d}")
NAV_CORRECTION = ("navigate", "{d}", "--compass-correction", "{w}/correction.yaml")
DEPTH = (
    "depth", "{d}", "--loops", "{w}/loops.csv", "--tide", "{w}/tide.csv", "--atmospheric", "{w}/atmosphere.csv"
)  # fmt: skip
SLAM = ("slam", "{d}", "--loops", "{w}/loops.csv")
GRAPH = ("graph", "optimize", "{w}/graph.g2o", "--out", "{w}/out.g2o")
GRAPH_3D = ("graph", "optimize", "{w}/graph3d.g2o", "--out", "{w}/out.g2o")
SIMULATE = ("simulate", "{w}/mission.yaml", "--out", "{w}/simulated", "--no-images")
SETTINGS = ("process", "-q", "{d}", "--settings", "{w}/settings.yaml", "--only", "nav")
#: Outputs a command would write: none may exist after a failure.
OUTPUTS = ("out.g2o", "simulated", "plan.yaml")


@dataclass(frozen=True)
class Case:
    """One named corruption: what to break, the command to run, the file its error must name."""

    name: str
    names: str
    corrupt: Corrupt
    command: tuple[str, ...] = VALIDATE
    heavy: bool = False  # run in a fresh process: memory measured as its peak resident set


def cases() -> list[Case]:
    D, V = "dive/dive.yaml", "dive/vehicle.yaml"
    dvl, att, prs = "dive/nav/dvl.csv", "dive/nav/attitude.csv", "dive/nav/pressure.csv"
    gps, usbl, mag, idx = (
        "dive/nav/gps.csv",
        "dive/nav/usbl.csv",
        "dive/nav/magnetometer.csv",
        "dive/images/index.csv",
    )
    C, L, T, A, G, M = (
        "correction.yaml",
        "loops.csv",
        "tide.csv",
        "atmosphere.csv",
        "graph.g2o",
        "mission.yaml",
    )
    out = [
        # dive.yaml: hostile YAML
        Case("dive.yaml alias bomb", "dive.yaml", put(D, ALIAS_BOMB), heavy=True),
        Case("dive.yaml one alias", "dive.yaml", append(D, "extra: &x 1\nmore: *x\n")),
        Case("dive.yaml 100,000 nested lists", "dive.yaml", put(D, DEEP_LISTS)),
        Case("dive.yaml 100,000 nested mappings", "dive.yaml", put(D, DEEP_MAPS)),
        Case("dive.yaml nested 40 deep", "dive.yaml", append(D, NESTED_40)),
        Case("dive.yaml 17 MB", "dive.yaml", append(D, "# " + "x" * (17 * 2**20) + "\n")),
        Case("dive.yaml duplicate key", "dive.yaml", append(D, "name: again\n")),
        Case(
            "dive.yaml duplicate nested key",
            "dive.yaml",
            replace(D, "  latitude_deg: -14.05\n", "  latitude_deg: -14.05\n  latitude_deg: 3\n"),
        ),
        Case("dive.yaml not UTF-8", "dive.yaml", put(D, b"name: \xff\xfe\n")),
        Case("dive.yaml binary", "dive.yaml", put(D, bytes(range(256)) * 4)),
        Case("dive.yaml empty", "dive.yaml", put(D, "")),
        Case("dive.yaml only a comment", "dive.yaml", put(D, "# nothing\n")),
        Case("dive.yaml a list", "dive.yaml", put(D, "- a\n- b\n")),
        Case("dive.yaml a scalar", "dive.yaml", put(D, "dive\n")),
        Case("dive.yaml a named pipe", "dive.yaml", fifo(D)),
        Case("dive.yaml a folder", "dive.yaml", folder(D)),
        Case("dive.yaml missing", "dive.yaml", remove(D)),
        Case("dive.yaml syntax error", "dive.yaml", append(D, "oops: [1, 2\n")),
        Case("dive.yaml tab indentation", "dive.yaml", replace(D, "  latitude_deg", "\tlatitude_deg")),
        Case(
            "dive.yaml !!timestamp tag", "dive.yaml", replace(D, "start_time: '", "start_time: !!timestamp '")
        ),
        Case("dive.yaml !!python tag", "dive.yaml", append(D, "x: !!python/object/apply:os.system [ls]\n")),
        Case("dive.yaml !!binary tag", "dive.yaml", append(D, "x: !!binary 'AAAA'\n")),
        Case("dive.yaml merge key", "dive.yaml", append(D, "<<: {name: merged}\n")),
        Case("dive.yaml list as a key", "dive.yaml", append(D, "? [a, b]\n: 1\n")),
        Case(
            "dive.yaml 1000-digit integer",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: " + "9" * 1000),
        ),
        Case("dive.yaml 1 MB unknown key", "dive.yaml", append(D, "k" * 2**20 + ": 1\n")),
        Case(
            "dive.yaml 1 MB heading_reference",
            "dive.yaml",
            replace(D, "heading_reference: magnetic", "heading_reference: " + "m" * 2**20),
        ),
        # dive.yaml: schema
        Case("dive.yaml unknown key", "dive.yaml", set_key(D, "origin.altitude_m", 3)),
        Case("dive.yaml wrong format", "dive.yaml", set_key(D, "format", "auvnav-dive/2")),
        Case("dive.yaml no format", "dive.yaml", del_key(D, "format")),
        Case("dive.yaml no name", "dive.yaml", del_key(D, "name")),
        Case("dive.yaml name a list", "dive.yaml", set_key(D, "name", [1, 2])),
        Case("dive.yaml no origin", "dive.yaml", del_key(D, "origin")),
        Case("dive.yaml latitude NaN", "dive.yaml", replace(D, "latitude_deg: -14.05", "latitude_deg: .nan")),
        Case("dive.yaml latitude 91", "dive.yaml", set_key(D, "origin.latitude_deg", 91.0)),
        Case(
            "dive.yaml longitude infinite",
            "dive.yaml",
            replace(D, "longitude_deg: 121.78", "longitude_deg: -.inf"),
        ),
        Case("dive.yaml latitude text", "dive.yaml", set_key(D, "origin.latitude_deg", "south")),
        Case("dive.yaml no start_time", "dive.yaml", del_key(D, "start_time")),
        Case("dive.yaml start_time without zone", "dive.yaml", replace(D, "00:00:00Z", "00:00:00")),
        Case("dive.yaml start_time 1970", "dive.yaml", set_key(D, "start_time", "1970-01-01T00:00:00Z")),
        Case("dive.yaml start_time a number", "dive.yaml", set_key(D, "start_time", 1255564800)),
        Case("dive.yaml start_time 30 February", "dive.yaml", replace(D, "2009-10-15", "2009-02-30")),
        Case("dive.yaml start_time 2200", "dive.yaml", replace(D, "2009-10-15", "2200-10-15")),
        Case("dive.yaml no heading_reference", "dive.yaml", del_key(D, "heading_reference")),
        Case(
            "dive.yaml heading_reference yes",
            "dive.yaml",
            replace(D, "heading_reference: magnetic", "heading_reference: yes"),
        ),
        Case(
            "dive.yaml heading_reference on",
            "dive.yaml",
            replace(D, "heading_reference: magnetic", "heading_reference: on"),
        ),
        Case(
            "dive.yaml heading_reference false",
            "dive.yaml",
            replace(D, "heading_reference: magnetic", "heading_reference: false"),
        ),
        Case("dive.yaml heading_reference north", "dive.yaml", set_key(D, "heading_reference", "north")),
        Case(
            "dive.yaml declination NaN",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: .nan"),
        ),
        Case(
            "dive.yaml declination infinite",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: .inf"),
        ),
        Case("dive.yaml declination 500", "dive.yaml", set_key(D, "declination_deg", 500.0)),
        Case("dive.yaml declination text", "dive.yaml", set_key(D, "declination_deg", "east")),
        Case(
            "dive.yaml declination true",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: true"),
        ),
        Case("dive.yaml no pressure block", "dive.yaml", del_key(D, "pressure")),
        Case("dive.yaml no pressure type", "dive.yaml", del_key(D, "pressure.type")),
        Case("dive.yaml pressure type on", "dive.yaml", replace(D, "type: absolute", "type: on")),
        Case("dive.yaml absolute without atmospheric", "dive.yaml", del_key(D, "pressure.atmospheric_dbar")),
        Case(
            "dive.yaml atmospheric NaN",
            "dive.yaml",
            replace(D, "atmospheric_dbar: 10.1325", "atmospheric_dbar: .NaN"),
        ),
        Case("dive.yaml atmospheric in hPa", "dive.yaml", set_key(D, "pressure.atmospheric_dbar", 1013.25)),
        Case("dive.yaml vehicle empty", "dive.yaml", set_key(D, "vehicle", "")),
        Case("dive.yaml vehicle absolute outside", "dive.yaml", set_key(D, "vehicle", "/etc/passwd")),
        Case("dive.yaml vehicle ../ outside", "dive.yaml", set_key(D, "vehicle", "../correction.yaml")),
        Case("dive.yaml vehicle missing", "vehicle", set_key(D, "vehicle", "nowhere.yaml")),
        Case("dive.yaml vehicle a folder", "nav", set_key(D, "vehicle", "nav")),
        Case("dive.yaml a link outside", "dive.yaml", link(D, "elsewhere/dive.yaml")),
        # vehicle.yaml
        Case(
            "vehicle NaN velocity sigma", "vehicle.yaml", set_key(V, "dvl.velocity_sigma_mps", float("nan"))
        ),
        Case("vehicle negative velocity sigma", "vehicle.yaml", set_key(V, "dvl.velocity_sigma_mps", -1.0)),
        Case("vehicle zero heading sigma", "vehicle.yaml", set_key(V, "compass.heading_sigma_deg", 0.0)),
        Case(
            "vehicle infinite pressure sigma", "vehicle.yaml", set_key(V, "pressure.sigma_dbar", float("inf"))
        ),
        Case("vehicle heading sigma 500 deg", "vehicle.yaml", set_key(V, "compass.heading_sigma_deg", 500.0)),
        Case("vehicle gps sigma text", "vehicle.yaml", set_key(V, "gps.sigma_m", "three")),
        Case("vehicle usbl sigma negative", "vehicle.yaml", set_key(V, "usbl.sigma_m", -5.0)),
        Case(
            "vehicle rotation not a rotation",
            "vehicle.yaml",
            set_key(V, "dvl.mount.R_body_sensor", [[1, 0, 0], [0, 1, 0], [0, 0, 2]]),
        ),
        Case(
            "vehicle rotation ragged",
            "vehicle.yaml",
            set_key(V, "dvl.mount.R_body_sensor", [[1, 0], [0, 1, 0]]),
        ),
        Case("vehicle rotation and rpy", "vehicle.yaml", set_key(V, "compass.mount.rpy_deg", [0, 0, 0])),
        Case(
            "vehicle rpy two numbers",
            "vehicle.yaml",
            edit_yaml(V, lambda d: d["gps"]["mount"].update(R_body_sensor=None, rpy_deg=[0, 1])),
        ),
        Case("vehicle lever arm 1 km", "vehicle.yaml", set_key(V, "dvl.mount.lever_arm_m", [1000.0, 0, 0])),
        Case(
            "vehicle lever arm NaN", "vehicle.yaml", set_key(V, "dvl.mount.lever_arm_m", [float("nan"), 0, 0])
        ),
        Case("vehicle unknown key", "vehicle.yaml", set_key(V, "dvl.frequency_khz", 1200)),
        Case("vehicle alias bomb", "vehicle.yaml", put(V, ALIAS_BOMB)),
        Case("vehicle duplicate key", "vehicle.yaml", append(V, "name: again\n")),
        Case("vehicle not UTF-8", "vehicle.yaml", put(V, b"\xff\xff\xff")),
        Case("vehicle a named pipe", "vehicle.yaml", fifo(V)),
        Case("vehicle empty", "vehicle.yaml", put(V, "")),
        Case("vehicle a link outside", "vehicle.yaml", link(V, "elsewhere/vehicle.yaml")),
        Case("stereo K 2x2", "vehicle.yaml", set_key(V, "stereo.left.K", [[50, 0], [0, 50]])),
        Case(
            "stereo K negative focal",
            "vehicle.yaml",
            set_key(V, "stereo.left.K", [[-50, 0, 31.5], [0, 50, 23.5], [0, 0, 1]]),
        ),
        Case(
            "stereo K NaN",
            "vehicle.yaml",
            set_key(V, "stereo.right.K", [[float("nan"), 0, 31.5], [0, 50, 23.5], [0, 0, 1]]),
        ),
        Case("stereo width 0", "vehicle.yaml", set_key(V, "stereo.left.width", 0)),
        Case("stereo width 10^9", "vehicle.yaml", set_key(V, "stereo.left.width", 10**9)),
        Case("stereo sizes differ", "vehicle.yaml", set_key(V, "stereo.right.width", 32)),
        Case(
            "stereo right camera on the left",
            "vehicle.yaml",
            set_key(V, "stereo.t_right_left_m", [0.1, 0.0, 0.0]),
        ),
        Case("stereo three distortion terms", "vehicle.yaml", set_key(V, "stereo.left.D", [0.0, 0.0, 0.0])),
        Case(
            "stereo R not a rotation",
            "vehicle.yaml",
            set_key(V, "stereo.R_right_left", [[2, 0, 0], [0, 1, 0], [0, 0, 1]]),
        ),
        Case("stereo zero baseline", "vehicle.yaml", set_key(V, "stereo.t_right_left_m", [0.0, 0.0, 0.0])),
        Case("stereo inline and a file", "vehicle.yaml", set_key(V, "stereo.calibration_file", "stereo.yml")),
        # vehicle.yaml: stereo calibration files
        Case("calibration absolute outside", "vehicle.yaml", opencv_calibration("/etc/hosts")),
        Case("calibration ../ outside", "vehicle.yaml", opencv_calibration("../stereo.yml")),
        Case("calibration missing", "missing.yml", opencv_calibration("missing.yml")),
        Case(
            "calibration without format",
            "vehicle.yaml",
            both(opencv_calibration("stereo.yml"), del_key(V, "stereo.calibration_format")),
        ),
        Case(
            "calibration not FileStorage",
            "stereo.yml",
            opencv_calibration("stereo.yml", "this is not a calibration\n"),
        ),
        Case("calibration binary", "stereo.yml", opencv_calibration("stereo.yml", bytes(range(256)))),
        Case(
            "calibration a named pipe",
            "stereo.yml",
            both(opencv_calibration("stereo.yml"), fifo("dive/stereo.yml")),
        ),
        Case(
            "calibration without K1",
            "stereo.yml",
            opencv_calibration("stereo.yml", "%YAML:1.0\nimage_width: 64\nimage_height: 48\n"),
        ),
        Case("calibration NaN matrix", "stereo.yml", opencv_calibration("stereo.yml", nan_matrix=True)),
        Case(
            "calibration XML entity",
            "stereo.yml",
            opencv_calibration(
                "stereo.yml",
                '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaa">]><opencv_storage>&a;</opencv_storage>',
            ),
        ),
        Case("calibration ros one file", "vehicle.yaml", ros_calibration(["left.yaml"])),
        Case("calibration ros NaN in K", "left.yaml", ros_calibration(["left.yaml", "right.yaml"], nan=True)),
        Case(
            "calibration ros width text",
            "left.yaml",
            ros_calibration(["left.yaml", "right.yaml"], width="wide"),
        ),
        Case(
            "calibration ros alias bomb",
            "left.yaml",
            both(ros_calibration(["left.yaml", "right.yaml"]), put("dive/left.yaml", ALIAS_BOMB)),
        ),
        # streams
        Case("dvl missing", "nav/dvl.csv", remove(dvl)),
        Case("attitude missing", "nav/attitude.csv", remove(att)),
        Case("pressure missing", "nav/pressure.csv", remove(prs)),
        Case("dvl missing column", "nav/dvl.csv", rename_column(dvl, "vx_mps", "vx")),
        Case("dvl duplicate column", "nav/dvl.csv", rename_column(dvl, "vy_mps", "vx_mps")),
        Case("dvl NaN velocity", "nav/dvl.csv", cell(dvl, 3, "vx_mps", "nan")),
        Case("dvl infinite velocity", "nav/dvl.csv", cell(dvl, 3, "vy_mps", "-inf")),
        Case("dvl text velocity", "nav/dvl.csv", cell(dvl, 3, "vz_mps", "fast")),
        Case("dvl 1 MB text velocity", "nav/dvl.csv", cell(dvl, 3, "vz_mps", "f" * 60_000)),
        Case("dvl valid maybe", "nav/dvl.csv", cell(dvl, 3, "valid", "maybe")),
        Case("dvl no valid sample", "nav/dvl.csv", column(dvl, "valid", lambda v: "0")),
        Case("dvl velocity in cm/s", "nav/dvl.csv", column(dvl, "vx_mps", lambda v: repr(float(v) * 100))),
        Case("dvl every velocity NaN", "nav/dvl.csv", column(dvl, "vx_mps", lambda v: "NaN")),
        Case("dvl 200 MB field", "nav/dvl.csv", big_field(dvl, "vx_mps", 200), heavy=True),
        Case("dvl 100 KB line", "nav/dvl.csv", cell(dvl, 2, "vx_mps", "1" * 100_000)),
        Case("dvl binary", "nav/dvl.csv", put(dvl, bytes(range(256)) * 8)),
        Case("dvl not UTF-8", "nav/dvl.csv", put(dvl, b"t,vx_mps\n1,\xe9\n")),
        Case("dvl empty file", "nav/dvl.csv", put(dvl, "")),
        Case("dvl header only", "nav/dvl.csv", edit_lines(dvl, lambda lines: lines[:1])),
        Case("dvl unbalanced quote", "nav/dvl.csv", cell(dvl, 2, "vx_mps", '"0.5')),
        Case(
            "dvl ragged row",
            "nav/dvl.csv",
            edit_lines(dvl, lambda lines: [*lines[:3], lines[3] + ",1,2,3", *lines[4:]]),
        ),
        Case("dvl a folder", "nav/dvl.csv", folder(dvl)),
        Case("dvl a named pipe", "nav/dvl.csv", fifo(dvl)),
        Case(
            "dvl a broken link",
            "nav/dvl.csv",
            both(remove(dvl), lambda w: (w / dvl).symlink_to(w / "nowhere.csv")),
        ),
        Case("dvl a link outside", "nav/dvl.csv", link(dvl, "elsewhere/dvl.csv")),
        Case("gps csv and parquet", "nav/gps.csv", also_parquet(gps)),
        Case(
            "gps parquet garbage",
            "nav/gps.parquet",
            both(remove(gps), put(gps.replace(".csv", ".parquet"), b"PAR1garbagePAR1")),
        ),
        Case(
            "gps parquet missing column",
            "nav/gps.parquet",
            parquet_copy(gps, lambda f: f.drop(columns=["sigma_m"])),
        ),
        Case(
            "gps parquet text values",
            "nav/gps.parquet",
            parquet_copy(gps, lambda f: f.assign(sigma_m="three")),
        ),
        Case(
            "gps parquet NaN", "nav/gps.parquet", parquet_copy(gps, lambda f: f.assign(sigma_m=float("nan")))
        ),
        Case(
            "attitude heading in radians",
            "nav/attitude.csv",
            column(att, "heading_deg", lambda v: repr(float(np.radians(float(v))))),
        ),
        Case("attitude pitch 120", "nav/attitude.csv", cell(att, 5, "pitch_deg", "120")),
        Case(
            "pressure in pascals",
            "nav/pressure.csv",
            column(prs, "pressure_dbar", lambda v: repr(float(v) * 1e4)),
        ),
        Case("pressure NaN", "nav/pressure.csv", cell(prs, 7, "pressure_dbar", "NaN")),
        Case(
            "pressure out of order",
            "nav/pressure.csv",
            edit_lines(prs, lambda x: [*x[:10], x[11], x[10], *x[12:]]),
        ),
        Case(
            "pressure duplicate time",
            "nav/pressure.csv",
            edit_lines(prs, lambda x: [*x[:21], x[20], *x[22:]]),
        ),
        Case("pressure times in ms", "nav/pressure.csv", column(prs, "t", lambda v: repr(float(v) * 1000))),
        Case("dvl times from 0", "nav/dvl.csv", shift(dvl, -START)),
        Case(
            "every stream from 0",
            "start_time",
            both(*(shift(f, -START) for f in (dvl, att, prs, mag, gps, usbl, idx))),
        ),
        Case("attitude in 1970", "nav/attitude.csv", shift(att, -START + 3600)),
        Case("dvl in GPS time", "nav/dvl.csv", shift(dvl, -315964800 + 15)),
        Case("attitude local time +10 h", "nav/attitude.csv", shift(att, 10 * 3600)),
        Case("gps six hours later", "nav/gps.csv", shift(gps, 6 * 3600)),
        Case(
            "pressure ends ten days later", "nav/pressure.csv", cell(prs, -1, "t", repr(START + 10 * 86400))
        ),
        Case("magnetometer text", "nav/magnetometer.csv", cell(mag, 2, "mx", "north")),
        Case(
            "gps in radians",
            "nav/gps.csv",
            both(
                column(gps, "latitude_deg", lambda v: repr(float(np.radians(float(v))))),
                column(gps, "longitude_deg", lambda v: repr(float(np.radians(float(v))))),
            ),
        ),
        Case(
            "gps in the other hemisphere",
            "nav/gps.csv",
            column(gps, "latitude_deg", lambda v: repr(-float(v))),
        ),
        Case("gps sigma zero", "nav/gps.csv", cell(gps, 1, "sigma_m", "0")),
        Case("gps latitude 95", "nav/gps.csv", cell(gps, 1, "latitude_deg", "95")),
        Case("usbl depth 20 km", "nav/usbl.csv", cell(usbl, 1, "depth_m", "20000")),
        Case(
            "stream 1 MB column name",
            "nav/dvl.csv",
            edit_lines(dvl, lambda x: [x[0].replace("vx_mps", "v" * 2**20), *x[1:]]),
        ),
        # images
        Case("image index ../ name", "images/index.csv", cell(idx, 1, "left", "../../etc/passwd")),
        Case("image index absolute name", "images/index.csv", cell(idx, 2, "right", "/etc/passwd")),
        Case("image index empty name", "images/index.csv", cell(idx, 2, "right", "")),
        Case("image index name of 5000 digits", "images/index.csv", cell(idx, 1, "left", "9" * 5000)),
        Case(
            "image link outside", "images/index.csv", link("dive/images/left/0000.png", "elsewhere/0000.png")
        ),
        Case(
            "images folder a link outside",
            "images/index.csv",
            both(
                lambda w: shutil.move(w / "dive/images/left", w / "left"),
                lambda w: (w / "dive/images/left").symlink_to(w / "left"),
            ),
        ),
        Case("image index a day later", "images/index.csv", shift(idx, 86400 * 2)),
        Case(
            "image index out of order",
            "images/index.csv",
            edit_lines(idx, lambda x: [x[0], x[2], x[1], *x[3:]]),
        ),
        Case("image of the wrong size", "images/left/0000.png", image("dive/images/left/0000.png", 32, 24)),
        # stage commands on a bad dive: the stage's own message, one line
        Case(
            "navigate: declination NaN",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: .nan"),
            NAVIGATE,
        ),
        Case(
            "navigate: NaN vehicle noise",
            "vehicle.yaml",
            set_key(V, "dvl.velocity_sigma_mps", float("nan")),
            NAVIGATE,
        ),
        Case(
            "navigate: negative depth noise",
            "vehicle.yaml",
            set_key(V, "pressure.sigma_dbar", -0.1),
            NAVIGATE,
        ),
        Case("navigate: streams in 1970", "nav/dvl.csv", shift(dvl, -START), NAVIGATE),
        Case(
            "navigate: GPS in radians",
            "nav/gps.csv",
            column(gps, "latitude_deg", lambda v: repr(float(np.radians(float(v))))),
            NAVIGATE,
        ),
        Case("navigate: vehicle outside", "dive.yaml", set_key(D, "vehicle", "../correction.yaml"), NAVIGATE),
        Case("navigate: stream twice", "nav/gps.csv", also_parquet(gps), NAVIGATE),
        Case(
            "navigate: heading_reference on",
            "dive.yaml",
            replace(D, "heading_reference: magnetic", "heading_reference: on"),
            NAVIGATE,
        ),
        Case(
            "navigate: products/nav a file",
            "products/nav",
            both(remove("dive/products/nav"), put("dive/products/nav", "x")),
            NAVIGATE,
        ),
        Case(
            "navigate: products a file",
            "products",
            both(remove("dive/products"), put("dive/products", "x")),
            NAVIGATE,
        ),
        Case("navigate: alias bomb", "dive.yaml", put(D, ALIAS_BOMB), NAVIGATE),
        Case(
            "process: declination infinite",
            "dive.yaml",
            replace(D, "declination_deg: 1.7", "declination_deg: .inf"),
            PROCESS,
        ),
        Case("process: dvl NaN", "nav/dvl.csv", cell(dvl, 3, "vx_mps", "nan"), PROCESS),
        Case("process: image outside", "images/index.csv", cell(idx, 1, "left", "../../etc/passwd"), PROCESS),
        Case(
            "loops: stereo sizes differ",
            "vehicle.yaml",
            set_key(V, "stereo.right.width", 32),
            ("loops", "{d}"),
        ),
        # compass correction (navigate --compass-correction)
        Case("correction not UTF-8", "correction.yaml", put(C, b"\xff\xfe\x00"), NAV_CORRECTION),
        Case("correction alias bomb", "correction.yaml", put(C, ALIAS_BOMB), NAV_CORRECTION),
        Case("correction deep nesting", "correction.yaml", put(C, DEEP_LISTS), NAV_CORRECTION),
        Case("correction no table", "correction.yaml", del_key(C, "table"), NAV_CORRECTION),
        Case("correction unknown key", "correction.yaml", set_key(C, "flavour", "vanilla"), NAV_CORRECTION),
        Case("correction 1 MB unknown key", "correction.yaml", set_key(C, "k" * 2**20, 1), NAV_CORRECTION),
        Case("correction wrong format", "correction.yaml", set_key(C, "format", "other/1"), NAV_CORRECTION),
        Case("correction negative harmonics", "correction.yaml", set_key(C, "harmonics", -1), NAV_CORRECTION),
        Case("correction 10^9 harmonics", "correction.yaml", set_key(C, "harmonics", 10**9), NAV_CORRECTION),
        Case("correction a0 NaN", "correction.yaml", set_key(C, "a0_deg", float("nan")), NAV_CORRECTION),
        Case("correction a0 yes", "correction.yaml", replace(C, "a0_deg: ", "a0_deg: yes #"), NAV_CORRECTION),
        Case("correction a_deg short", "correction.yaml", set_key(C, "a_deg", [1.0]), NAV_CORRECTION),
        Case(
            "correction table edited",
            "correction.yaml",
            edit_yaml(C, lambda d: d["table"][10].__setitem__(1, 5.0)),
            NAV_CORRECTION,
        ),
        Case(
            "correction table 10 rows",
            "correction.yaml",
            edit_yaml(C, lambda d: d.__setitem__("table", d["table"][:10])),
            NAV_CORRECTION,
        ),
        Case(
            "correction table text",
            "correction.yaml",
            edit_yaml(C, lambda d: d["table"].__setitem__(3, ["a", "b"])),
            NAV_CORRECTION,
        ),
        Case(
            "correction covariance not symmetric",
            "correction.yaml",
            set_key(
                C,
                "covariance_deg2",
                [[1.0 if i == j else (0.5 if i < j else 0.0) for j in range(7)] for i in range(7)],
            ),
            NAV_CORRECTION,
        ),
        Case(
            "correction covariance NaN",
            "correction.yaml",
            set_key(C, "covariance_deg2", [[float("nan")] * 7] * 7),
            NAV_CORRECTION,
        ),
        Case(
            "correction unknown constant source",
            "correction.yaml",
            set_key(C, "constant.source", "guess"),
            NAV_CORRECTION,
        ),
        Case("correction duplicate key", "correction.yaml", append(C, "harmonics: 3\n"), NAV_CORRECTION),
        Case("correction empty", "correction.yaml", put(C, ""), NAV_CORRECTION),
        Case("correction a named pipe", "correction.yaml", fifo(C), NAV_CORRECTION),
        Case("correction a folder", "correction.yaml", folder(C), NAV_CORRECTION),
        Case("correction missing", "correction.yaml", remove(C), NAV_CORRECTION),
        Case(
            "simulate: correction NaN",
            "correction.yaml",
            set_key(C, "a0_deg", float("nan")),
            (
                "simulate",
                "transit",
                "--out",
                "{w}/simulated",
                "--no-images",
                "--compass-correction",
                "{w}/correction.yaml",
            ),
        ),
        # loop closures (depth and slam check them alike)
        Case("loops pose out of range (depth)", "loops.csv", cell(L, 1, "j", "5000"), DEPTH),
        Case("loops pose out of range (slam)", "loops.csv", cell(L, 1, "j", "5000"), SLAM),
        Case("loops self-loop (depth)", "loops.csv", cell(L, 2, "j", "1"), DEPTH),
        Case("loops self-loop (slam)", "loops.csv", cell(L, 2, "j", "1"), SLAM),
        Case("loops covariance not PD (depth)", "loops.csv", cell(L, 1, "cov00", "-1e-3"), DEPTH),
        Case("loops covariance not PD (slam)", "loops.csv", cell(L, 1, "cov00", "-1e-3"), SLAM),
        Case("loops covariance 1e300", "loops.csv", cell(L, 1, "cov01", "1e300"), DEPTH),
        Case("loops pose 1e30", "loops.csv", cell(L, 1, "i", "1e30"), DEPTH),
        Case("loops pose 1.5", "loops.csv", cell(L, 1, "i", "1.5"), SLAM),
        Case("loops of another dive", "loops.csv", column(L, "t_i", lambda v: repr(float(v) + 100)), DEPTH),
        Case("loops NaN", "loops.csv", cell(L, 3, "x_m", "nan"), SLAM),
        Case("loops missing column", "loops.csv", rename_column(L, "cov33", "cov_33"), DEPTH),
        Case(
            "loops 3000 bad rows",
            "loops.csv",
            edit_lines(L, lambda x: [x[0], *([x[1].replace(",4,", ",4000,", 1)] * 3000)]),
            SLAM,
        ),
        Case("loops a folder", "loops.csv", folder(L), DEPTH),
        Case("loops binary", "loops.csv", put(L, bytes(range(256)) * 4), SLAM),
        Case("loops header only", "loops.csv", edit_lines(L, lambda x: x[:1]), DEPTH),
        # tide constituents (depth --tide)
        Case("tide not UTF-8", "tide.csv", put(T, b"name,amplitude_m,phase_deg\nM2,\xff,1\n"), DEPTH),
        Case("tide unknown constituent", "tide.csv", replace(T, "K1,", "X9,"), DEPTH),
        Case("tide Z0 row", "tide.csv", replace(T, "K1,", "Z0,"), DEPTH),
        Case("tide negative amplitude", "tide.csv", replace(T, "M2,0.8", "M2,-0.8"), DEPTH),
        Case("tide phase 400", "tide.csv", edit_lines(T, lambda x: [*x[:-1], "S2,0.1,400"]), DEPTH),
        Case("tide phase NaN", "tide.csv", edit_lines(T, lambda x: [*x[:-1], "S2,0.1,nan"]), DEPTH),
        Case("tide constituent twice", "tide.csv", edit_lines(T, lambda x: [*x, x[-1]]), DEPTH),
        Case("tide comment after header", "tide.csv", append(T, "# mean_m: 3\n"), DEPTH),
        Case("tide bad header", "tide.csv", replace(T, "amplitude_m", "amp"), DEPTH),
        Case("tide ragged row", "tide.csv", append(T, "S2,0.1\n"), DEPTH),
        Case("tide a named pipe", "tide.csv", fifo(T), DEPTH),
        Case("tide 2 MB", "tide.csv", append(T, "#" * 2 * 2**20), DEPTH),
        Case("tide NUL byte", "tide.csv", append(T, "S2,0.1,\x0010\n"), DEPTH),
        Case("tide empty", "tide.csv", put(T, ""), DEPTH),
        # atmospheric series (depth --atmospheric)
        Case("atmospheric not UTF-8", "atmosphere.csv", put(A, b"t,pressure_dbar\n1,\xff\n"), DEPTH),
        Case("atmospheric missing column", "atmosphere.csv", replace(A, "pressure_dbar", "p"), DEPTH),
        Case("atmospheric NaN", "atmosphere.csv", append(A, f"{START + 5000},nan\n"), DEPTH),
        Case("atmospheric in hPa", "atmosphere.csv", replace(A, "10.13", "1013."), DEPTH),
        Case("atmospheric duplicate time", "atmosphere.csv", edit_lines(A, lambda x: [*x, x[-1]]), DEPTH),
        Case("atmospheric a named pipe", "atmosphere.csv", fifo(A), DEPTH),
        Case("atmospheric NUL byte", "atmosphere.csv", append(A, "1\x00,2\n"), DEPTH),
        Case("atmospheric empty", "atmosphere.csv", put(A, ""), DEPTH),
        Case("atmospheric text", "atmosphere.csv", append(A, f"{START + 5000},high\n"), DEPTH),
        # pose graphs (graph optimize)
        Case("g2o vertex id 2^63", "graph.g2o", append(G, "VERTEX_SE2 9223372036854775808 0 0 0\n"), GRAPH),
        Case("g2o vertex id 2^64", "graph.g2o", append(G, "VERTEX_SE2 18446744073709551616 0 0 0\n"), GRAPH),
        Case("g2o vertex id in Arabic digits", "graph.g2o", append(G, "VERTEX_SE2 \u0663 0 0 0\n"), GRAPH),
        Case("g2o unknown record", "graph.g2o", append(G, "VERTEX_XYZ 3 0 0 0\n"), GRAPH),
        Case("g2o too few fields", "graph.g2o", append(G, "VERTEX_SE2 3 0 0\n"), GRAPH),
        Case("g2o NaN", "graph.g2o", append(G, "VERTEX_SE2 3 nan 0 0\n"), GRAPH),
        Case(
            "g2o information not PD", "graph.g2o", append(G, "EDGE_SE2 0 2 1 0 0 -100 0 0 100 0 400\n"), GRAPH
        ),
        Case(
            "g2o information 1e300",
            "graph.g2o",
            append(G, "EDGE_SE2 0 2 1 0 0 1e300 1e300 0 1e300 0 400\n"),
            GRAPH,
        ),
        Case("g2o vertex twice", "graph.g2o", append(G, "VERTEX_SE2 1 0 0 0\n"), GRAPH),
        Case("g2o edge to nowhere", "graph.g2o", append(G, "EDGE_SE2 0 7 1 0 0 100 0 0 100 0 400\n"), GRAPH),
        Case("g2o self-loop", "graph.g2o", append(G, "EDGE_SE2 1 1 1 0 0 100 0 0 100 0 400\n"), GRAPH),
        Case("g2o 2D and 3D", "graph.g2o", append(G, "VERTEX_SE3:QUAT 5 0 0 0 0 0 0 1\n"), GRAPH),
        Case(
            "g2o quaternion norm 2",
            "graph3d.g2o",
            append("graph3d.g2o", "VERTEX_SE3:QUAT 5 0 0 0 0 0 0 2\n"),
            GRAPH_3D,
        ),
        Case("g2o TORO EQUIV", "graph.g2o", append(G, "EQUIV 0 1\n"), GRAPH),
        Case("g2o empty", "graph.g2o", put(G, ""), GRAPH),
        Case("g2o a named pipe", "graph.g2o", fifo(G), GRAPH),
        Case("g2o a folder", "graph.g2o", folder(G), GRAPH),
        Case("g2o missing", "graph.g2o", remove(G), GRAPH),
        Case(
            "g2o 200 MB line",
            "graph.g2o",
            append(G, "VERTEX_SE2 " + "1" * (200 * 2**20) + " 0 0 0\n"),
            GRAPH,
            heavy=True,
        ),
        Case("g2o binary", "graph.g2o", put(G, bytes(range(256)) * 16), GRAPH),
        Case(
            "g2o edges only, disconnected",
            "graph.g2o",
            put(G, "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n"),
            GRAPH,
        ),
        # missions (simulate MISSION.yaml; plan)
        Case("mission alias bomb", "mission.yaml", put(M, ALIAS_BOMB), SIMULATE),
        Case(
            "mission waypoint 10^12 m away",
            "mission.yaml",
            replace(M, "[15.0, 2.0]", "[1.0e+12, 2.0]"),
            SIMULATE,
            heavy=True,
        ),
        Case(
            "mission infinite surface wait",
            "mission.yaml",
            replace(M, "duration_s: 120.0", "duration_s: .inf"),
            SIMULATE,
        ),
        Case(
            "mission surface wait 10^9 s",
            "mission.yaml",
            replace(M, "duration_s: 120.0", "duration_s: 1.0e+9"),
            SIMULATE,
        ),
        Case(
            "mission 100 hours of spinning",
            "mission.yaml",
            replace(M, "{type: descend}", "{type: spin, turns: 1000, rate_deg_s: 1}"),
            SIMULATE,
        ),
        Case(
            "mission 100 days of lines",
            "mission.yaml",
            replace(M, "{type: descend}", "{type: line, speed_mps: 0.01, waypoints: [[0, 0], [90000, 0]]}"),
            SIMULATE,
        ),
        Case("mission speed 0", "mission.yaml", replace(M, "speed_mps: 0.5", "speed_mps: 0"), SIMULATE),
        Case("mission speed NaN", "mission.yaml", replace(M, "speed_mps: 0.5", "speed_mps: .nan"), SIMULATE),
        Case(
            "mission unknown segment",
            "mission.yaml",
            replace(M, "{type: descend}", "{type: teleport}"),
            SIMULATE,
        ),
        Case("mission unknown key", "mission.yaml", append(M, "colour: yellow\n"), SIMULATE),
        Case("mission not UTF-8", "mission.yaml", put(M, b"format: \xff\n"), SIMULATE),
        Case("mission deep nesting", "mission.yaml", put(M, DEEP_MAPS), SIMULATE),
        Case("mission duplicate key", "mission.yaml", append(M, "name: again\n"), SIMULATE),
        Case("mission no format", "mission.yaml", replace(M, "format: auvnav-mission/1\n", ""), SIMULATE),
        Case(
            "plan survey 10^-9 m spacing",
            "spacing_m",
            lambda w: None,
            ("plan", "survey", "--spacing-m", "1e-9", "--out", "{w}/plan.yaml"),
        ),
        Case(
            "plan navcheck 10^12 m legs",
            "leg",
            lambda w: None,
            ("plan", "navcheck", "--leg-m", "1e12", "--out", "{w}/plan.yaml"),
        ),
        Case(
            "plan transit 10^7 legs",
            "legs",
            lambda w: None,
            ("plan", "transit", "--legs", "10000000", "--out", "{w}/plan.yaml"),
        ),
        Case(
            "simulate survey 10^-9 m spacing",
            "spacing_m",
            lambda w: None,
            ("simulate", "survey", "--spacing-m", "1e-9", "--out", "{w}/simulated", "--no-images"),
        ),
        # settings files (process --settings)
        Case("settings alias bomb", "settings.yaml", put("settings.yaml", ALIAS_BOMB), SETTINGS),
        Case("settings unknown stage", "settings.yaml", put("settings.yaml", "warp: {speed: 9}\n"), SETTINGS),
        Case(
            "settings unknown setting",
            "settings.yaml",
            put("settings.yaml", "slam: {robustness: 3}\n"),
            SETTINGS,
        ),
        Case(
            "settings NaN",
            "settings.yaml",
            put("settings.yaml", "slam: {compass_sigma_deg: .nan}\n"),
            SETTINGS,
        ),
        Case(
            "settings boolean trap", "settings.yaml", put("settings.yaml", "slam: {robust: off}\n"), SETTINGS
        ),
    ]
    return out


def opencv_calibration(name: str, content: str | bytes | None = None, *, nan_matrix: bool = False) -> Corrupt:
    """vehicle.yaml reads its stereo rig from ``name`` (OpenCV), with ``content`` written there."""

    def f(w: Path) -> None:
        data = yaml.safe_load((w / "dive/vehicle.yaml").read_text())
        data["stereo"] = {"calibration_file": name, "calibration_format": "opencv"}
        (w / "dive/vehicle.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        target = w / "dive" / name
        if content is not None:
            put(str(target.relative_to(w)), content)(w)
        elif not name.startswith(("/", "..")) and name != "missing.yml":
            shutil.copy(w / "stereo.yml", target)
            if nan_matrix:
                text = target.read_text().replace("50., 0., 31.5", ".nan, 0., 31.5", 1)
                target.write_text(text)

    return f


def ros_calibration(files: list[str], *, nan: bool = False, width: object = None) -> Corrupt:
    """vehicle.yaml reads its stereo rig from ROS camera_info ``files``."""

    def f(w: Path) -> None:
        data = yaml.safe_load((w / "dive/vehicle.yaml").read_text())
        data["stereo"] = {
            "calibration_file": files if len(files) > 1 else files[0],
            "calibration_format": "ros",
        }
        (w / "dive/vehicle.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        for name in files:
            shutil.copy(w / name, w / "dive" / name)
        if nan or width is not None:
            info = yaml.safe_load((w / "dive/left.yaml").read_text())
            if nan:
                info["camera_matrix"]["data"][0] = float("nan")
            if width is not None:
                info["image_width"] = width
            (w / "dive/left.yaml").write_text(yaml.safe_dump(info))

    return f


CASES = cases()

# ---------------------------------------------------------------------------------------------
# Running a case
# ---------------------------------------------------------------------------------------------

_CHILD = r"""
import os, sys
from auvnav.cli import main
try:
    code = main(sys.argv[1:])
finally:
    with open("/proc/self/status") as status:
        hwm = next(line for line in status if line.startswith("VmHWM"))
    with open(os.environ["AUVNAV_TEST_HWM"], "w") as out:
        out.write(hwm.split()[1])
sys.exit(code)
"""


def _snapshot(products: Path) -> dict[str, str]:
    """Every file under products/ (bookkeeping excepted) with its content's digest."""
    if not products.exists():
        return {}
    if not products.is_dir():
        return {".": hashlib.sha1(products.read_bytes()).hexdigest()}
    out = {}
    for path in sorted(products.rglob("*")):
        rel = str(path.relative_to(products))
        if rel in BOOKKEEPING or path.is_dir():
            continue
        out[rel] = hashlib.sha1(path.read_bytes()).hexdigest()
    return out


def _rss_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _can_reset_peak() -> bool:
    """Whether this process may reset its peak resident set (Linux 4.0+, ``/proc/self/clear_refs``)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


#: Without a resettable peak, every case runs in a fresh process (slower, as exact).
RESET_PEAK = _can_reset_peak()


def _peak_rss_mb() -> float:
    """The process's peak resident set (``VmHWM``) since it was last reset, MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmHWM in /proc/self/status")


def _run_here(args: list[str]) -> tuple[int, str, float]:
    """Exit code, stderr and the extra memory (MB) of a command run in this process: its peak
    resident set during the command (reset before it through ``/proc/self/clear_refs``, so what an
    earlier test of this worker used does not count), less its resident set before (C allocations
    included; tracemalloc would miss them and make the run five times slower)."""
    err, out = io.StringIO(), io.StringIO()
    Path("/proc/self/clear_refs").write_text("5")
    before = _rss_mb()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        code = main(args)
    return code, err.getvalue(), max(_peak_rss_mb() - before, 0.0)


def _run_fresh(args: list[str], tmp: Path) -> tuple[int, str, float]:
    """Exit code, stderr and peak resident set (MB) of a command run in a fresh process."""
    hwm = tmp / "hwm"
    env = {**os.environ, "AUVNAV_TEST_HWM": str(hwm), "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, *args], capture_output=True, env=env, timeout=120, check=False
    )
    return done.returncode, done.stderr.decode("utf-8", errors="replace"), int(hwm.read_text()) / 1024


@pytest.fixture(scope="module")
def samples(tmp_path_factory: pytest.TempPathFactory):
    """The valid samples, the dive with the products of an earlier navigate run."""
    s = bad_input.write_samples(tmp_path_factory.mktemp("samples"))
    code, err, _ = _run_fresh(["navigate", str(s.dive)], s.root)  # keeps this process's peak low
    assert code == 0, err
    assert (s.dive / "products/nav/filter.csv").is_file()
    return s


def test_catalogue_size() -> None:
    names = [c.name for c in CASES]
    assert len(names) == len(set(names)), "case names must be unique"
    assert len(CASES) >= 150


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_gives_one_line(case: Case, samples, tmp_path: Path) -> None:
    work = tmp_path / "w"
    shutil.copytree(samples.root, work, symlinks=True)
    case.corrupt(work)
    dive = work / "dive"
    before = _snapshot(dive / "products")
    args = [a.format(d=dive, w=work) for a in case.command]
    code, err, peak_mb = _run_fresh(args, tmp_path) if case.heavy or not RESET_PEAK else _run_here(args)
    lines = err.strip().splitlines()
    assert code == 1, f"exit {code}; stderr: {err[:2000]}"
    assert len(lines) == 1, f"{len(lines)} lines on stderr:\n{err[:3000]}"
    assert lines[0].startswith("auvnav: error: "), lines[0][:500]
    assert case.names in lines[0], f"the message does not name {case.names}: {lines[0][:500]}"
    assert len(lines[0]) < 1000, f"a line of {len(lines[0])} characters"
    assert peak_mb < MAX_MEMORY_MB, f"peak memory {peak_mb:.0f} MB"
    assert _snapshot(dive / "products") == before, "products/ changed"
    assert not [o for o in OUTPUTS if (work / o).exists()], "an output was written"


# ---------------------------------------------------------------------------------------------
# Nothing outside the dive is read unless --allow-outside is given, and then it is said
# ---------------------------------------------------------------------------------------------

_OPENED: list[str] | None = None  # the audit hook records opened paths here while it is a list


def _audit(event: str, args: tuple) -> None:
    if _OPENED is not None and event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
        _OPENED.append(os.fsdecode(args[0]))


def _inside(paths: list[str] | None, folder: str) -> list[str]:
    """The paths that really lead into ``folder``."""
    return sorted({p for p in paths or [] if os.path.realpath(p).startswith(folder + os.sep)})


def _outside_variants(outside: Path) -> dict[str, tuple[Corrupt, bool]]:
    """Every way a dive can name a file outside itself: name -> (corruption, allowed by the flag)."""

    def to_outside(rel: str) -> Corrupt:
        def f(w: Path) -> None:
            target = outside / Path(rel).name
            if not target.exists():
                shutil.copy(w / "dive" / rel, target)
            (w / "dive" / rel).unlink()
            (w / "dive" / rel).symlink_to(target)

        return f

    def calibration(name: str) -> Corrupt:
        def f(w: Path) -> None:
            shutil.copy(w / "stereo.yml", outside / "stereo.yml")
            data = yaml.safe_load((w / "dive/vehicle.yaml").read_text())
            data["stereo"] = {"calibration_file": name, "calibration_format": "opencv"}
            (w / "dive/vehicle.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
            if name == "stereo.yml":
                (w / "dive/stereo.yml").symlink_to(outside / "stereo.yml")

        return f

    def vehicle(name: str) -> Corrupt:
        def f(w: Path) -> None:
            shutil.copy(w / "dive/vehicle.yaml", outside / "vehicle.yaml")
            set_key("dive/dive.yaml", "vehicle", name)(w)

        return f

    def images_folder(w: Path) -> None:
        shutil.copytree(w / "dive/images/right", outside / "right")
        shutil.rmtree(w / "dive/images/right")
        (w / "dive/images/right").symlink_to(outside / "right")

    return {
        "vehicle named by ../": (
            vehicle(os.path.relpath(outside / "vehicle.yaml", outside.parent / "w/dive")),
            True,
        ),
        "vehicle named by an absolute path": (vehicle(str(outside / "vehicle.yaml")), True),
        "vehicle.yaml a link": (to_outside("vehicle.yaml"), True),
        "dive.yaml a link": (to_outside("dive.yaml"), True),
        "calibration named by ../": (
            calibration(os.path.relpath(outside / "stereo.yml", outside.parent / "w/dive")),
            True,
        ),
        "calibration a link": (calibration("stereo.yml"), True),
        "stream a link": (to_outside("nav/gps.csv"), True),
        "image a link": (to_outside("images/left/0000.png"), True),
        "images folder a link": (images_folder, True),
        "image index names ../": (cell("dive/images/index.csv", 1, "left", "../../outside/0000.png"), False),
    }


#: Variants also run through ``navigate --allow-outside`` (a stage: its reading and its key).
NAVIGATED = ("vehicle named by ../", "calibration a link", "stream a link", "image a link")


def test_no_read_outside_the_dive_without_being_said(samples, tmp_path: Path) -> None:
    global _OPENED
    sys.addaudithook(_audit)
    outside = tmp_path / "outside"
    for name, (corrupt, allowed) in _outside_variants(outside).items():
        shutil.rmtree(tmp_path / "w", ignore_errors=True)
        shutil.rmtree(outside, ignore_errors=True)
        outside.mkdir()
        shutil.copy(samples.dive / "images/left/0000.png", outside / "0000.png")
        work = tmp_path / "w"
        shutil.copytree(samples.root, work, symlinks=True)
        corrupt(work)
        dive = work / "dive"
        real_outside = str(outside.resolve())

        for command in (["validate", str(dive)], ["navigate", str(dive)]):
            _OPENED = []
            code, err, _ = _run_here(command)
            opened, _OPENED = _inside(_OPENED, real_outside), None
            lines = err.strip().splitlines()
            assert code == 1, f"{name}: {command[0]} exit {code}: {err}"
            assert len(lines) == 1 and "outside" in lines[0], f"{name}: {err}"
            assert not opened, f"{name}: {command[0]} read {opened} without --allow-outside"
        if not allowed:  # a name in the image index that leaves images/ is refused whatever the flag
            code, err, _ = _run_here(["validate", str(dive), "--allow-outside"])
            assert code == 1 and "outside images/" in err, f"{name}: {err}"
            continue
        commands = [["validate", str(dive), "--allow-outside"]]
        if name in NAVIGATED:  # a stage's own reading and its key, for one variant of each kind
            commands.append(["navigate", str(dive), "--allow-outside"])
        for command in commands:
            _OPENED = []
            code, err, _ = _run_here(command)
            opened, _OPENED = _inside(_OPENED, real_outside), None
            said = [line for line in err.splitlines() if "--allow-outside" in line and "outside" in line]
            assert code == 0, f"{name}: {command[0]} --allow-outside exit {code}: {err}"
            assert opened, f"{name}: nothing outside was read: is the variant right?"
            for path in opened:
                real = os.path.realpath(path)
                assert any(
                    real.startswith(os.path.realpath(word.rstrip(":,")))
                    for line in said
                    for word in line.split()
                    if word.startswith("/")
                ), f"{name}: {command[0]} read {path} and did not say so: {said}"
