"""Fuzzing every reader: whatever bytes a file holds, a reader returns or raises the project's own
error (:class:`~auvnav.errors.AuvnavError`) with bounded, short lines; nothing else escapes.

Each reader is a row of :data:`READERS`: the valid sample it starts from (``tests/bad_input.py``),
the name the fuzzed bytes are written under, and how to read them. The examples are the sample
mutated (a token replaced by a hostile one, a line deleted, doubled, swapped or cut, bytes
spliced in) or raw bytes. A new reader (an importer of ``auvnav.io``) is one more row.

Fast and repeatable by default (:data:`EXAMPLES` per reader, derandomized, so CI sees the same bytes
each run); ``AUVNAV_FUZZ_EXAMPLES=2000`` (or any number) is the random
long run for a benchmark. With ``-s`` each reader prints the examples it ran; with
``AUVNAV_FUZZ_REPORT=FILE`` it appends them to FILE (works under ``-n``).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auvnav.errors import AuvnavError


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


def _load_writers_module() -> ModuleType:
    """``tests/io/io_writers.py``: the independent writers of the vendor formats."""
    name = "auvnav_tests_io_writers"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).parent / "io" / "io_writers.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


#: Examples per reader, when set: the long run for a benchmark (the default is :attr:`Reader.examples`,
#: about a second or two of each reader).
EXAMPLES = int(os.environ["AUVNAV_FUZZ_EXAMPLES"]) if os.environ.get("AUVNAV_FUZZ_EXAMPLES") else None
#: Longest line an error may have, characters (values are quoted to 80; paths and words add the rest).
MAX_LINE = 600
#: Most lines an error may have (DiveFormatError says 12 problems and counts the rest).
MAX_LINES = 13

# Tokens people and attackers write where a value belongs.
HOSTILE = [
    "nan",
    "NaN",
    ".nan",
    "inf",
    "-inf",
    ".inf",
    "-.inf",
    "1e400",
    "-1e400",
    "1e308",
    "-1",
    "0",
    "-0",
    "",
    " ",
    "yes",
    "no",
    "on",
    "off",
    "true",
    "false",
    "True",
    "null",
    "~",
    "&a",
    "*a",
    "&a [1, 2]",
    "[",
    "]",
    "{",
    "}",
    "'",
    '"',
    "#",
    ",",
    ":",
    "- ",
    "\t",
    "\x00",
    "é",
    "9" * 30,
    "9" * 5000,
    "x" * 20000,
    "2009-02-30",
    "0x1F",
    "0o17",
    "1:30",
    "1_000",
    "9223372036854775808",
    "18446744073709551616",
    "-9223372036854775809",
    "\u0663",
    "\u00b2",
    "!!binary x",
    "!!timestamp x",
    "!!python/object:os.system x",
    "!!set {a}",
    "<<",
    "? ",
    "|",
    ">",
    "%YAML 1.1",
    "---",
    "...",
    "\r",
    "\u2028",
    "\ufeff",
    "1e-3",
    "012",
    "1.5",
    "1e30",
    "4.1e9",
    "1e12",
    "315964800",
    "-315964800",
    "EQUIV",
    "VERTEX_SE2",
    "EDGE3",
    "M2",
    "Z0",
    "../../etc/passwd",
    "/etc/passwd",
]
_SPLIT = re.compile(r"([,\s:\[\]{}]+)")


@st.composite
def mutated(draw: st.DrawFn, sample: bytes) -> bytes:
    """``sample`` with a few edits, or raw bytes."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.binary(max_size=3000))
    text = sample.decode("utf-8", errors="replace")
    lines = text.splitlines(keepends=True) or [""]
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["token", "token", "token", "delete", "double", "swap", "cut", "insert"]))
        k = draw(st.integers(0, len(lines) - 1))
        if op == "token":
            parts = _SPLIT.split(lines[k])
            at = draw(st.integers(0, max(len(parts) - 1, 0)))
            new = draw(st.sampled_from(HOSTILE) | st.text(max_size=12) | st.floats().map(repr))
            parts[at] = new
            lines[k] = "".join(parts)
        elif op == "delete" and len(lines) > 1:
            del lines[k]
        elif op == "double":
            lines.insert(k, lines[k])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        elif op == "cut":
            lines = lines[: k + 1]
            lines[k] = lines[k][: draw(st.integers(0, len(lines[k])))]
        elif op == "insert":
            lines.insert(k, draw(st.sampled_from(HOSTILE) | st.text(max_size=40)) + "\n")
    out = "".join(lines).encode("utf-8", errors="surrogatepass")
    if draw(st.integers(0, 7)) == 0:  # bytes that are not UTF-8, or a NUL
        at = draw(st.integers(0, len(out)))
        out = out[:at] + draw(st.sampled_from([b"\xff", b"\xc3", b"\x00", b"\xed\xa0\x80"])) + out[at:]
    return out


@dataclass(frozen=True)
class Reader:
    """One reader under fuzz.

    Parameters
    ----------
    name : str
    sample : callable(samples) -> Path
        The valid file it starts from.
    target : callable(work) -> Path
        Where the fuzzed bytes are written, inside ``work`` (a copy of the samples' folder).
    read : callable(path, work) -> object
        Reads the file; may raise AuvnavError. A reader that reports problems instead of raising
        returns them (a list of problems or strings) to have their lines checked too.
    examples : int
        Examples in the default (fast) run.
    prepare : callable(work), optional
        Makes the work folder ready once (e.g. removes the file the target replaces).
    """

    name: str
    sample: Callable[[object], Path]
    target: Callable[[Path], Path]
    read: Callable[[Path, Path], object]
    examples: int = 100
    prepare: Callable[[Path], None] | None = None


def _validate(path: Path, work: Path) -> object:
    from auvnav.dive import validate_dive

    report = validate_dive(work / "dive")
    return [*report.problems, *report.warnings]


def _in_dive(rel: str) -> Reader:
    return Reader(
        f"dive {rel}",
        lambda s, rel=rel: s.dive / rel,
        lambda work, rel=rel: work / "dive" / rel,
        _validate,
        examples=15,  # a whole dive is validated each time (about 60 ms)
    )


def _read_correction(path: Path, work: Path) -> object:
    from auvnav.compass.correction import read_correction

    return read_correction(path)


def _read_loops(path: Path, work: Path) -> object:
    from auvnav.vision.loopfile import check_loop_times, read_loops

    loops = read_loops(path, n_poses=bad_input.N_IMAGES)
    image_t = bad_input.START_S + 10.0 + __import__("numpy").arange(bad_input.N_IMAGES, dtype=float)
    check_loop_times(loops, image_t, str(path))
    return loops


def _read_g2o(path: Path, work: Path) -> object:
    from auvnav.slam.g2o import read_g2o

    return read_g2o(path)


def _read_tide(path: Path, work: Path) -> object:
    from auvnav.depth.tide import read_constituents

    return read_constituents(path, latitude_rad=-0.245)


def _read_atmospheric(path: Path, work: Path) -> object:
    from auvnav.depth.pressure import read_atmospheric

    return read_atmospheric(path)


def _read_mission(path: Path, work: Path) -> object:
    from auvnav.plan.missions import read_mission

    return read_mission(path)


def _read_ros(path: Path, work: Path) -> object:
    from auvnav.vehicle import read_ros_stereo

    return read_ros_stereo(path, work / "right.yaml")


def _read_opencv(path: Path, work: Path) -> object:
    from auvnav.vehicle import read_opencv_stereo

    return read_opencv_stereo(path)


def _read_settings(path: Path, work: Path) -> object:
    from auvnav.cli.stages import _settings_file
    from auvnav.pipeline import stage_named
    from auvnav.stagekit import make_settings

    return [
        make_settings(stage_named(name).settings, given, f"{path}: {name}", base=path.parent)
        for name, given in _settings_file(path).items()
    ]


def _importer(fmt: str, log: str, config: str | None = None) -> Reader:
    """An importer of :mod:`auvnav.io` under fuzz: one of its logs (under ``logs/``) mutated, imported
    into a new dive with the sample dive as the base (what the log lacks)."""

    def read(path: Path, work: Path) -> object:
        from auvnav.io import import_dive

        settings = None if config is None else work / "logs" / config
        return import_dive(
            fmt, [path], work / "imported", config=settings, base=work / "dive", overwrite=True
        )

    return Reader(
        f"import {fmt}", lambda s: s.root / "logs" / log, lambda w: w / "logs" / log, read, examples=25
    )


#: Every reader under fuzz. Add a row for a new reader.
READERS: list[Reader] = [
    _in_dive("dive.yaml"),
    _in_dive("vehicle.yaml"),
    _in_dive("nav/dvl.csv"),
    _in_dive("nav/attitude.csv"),
    _in_dive("nav/pressure.csv"),
    _in_dive("nav/magnetometer.csv"),
    _in_dive("nav/gps.csv"),
    _in_dive("nav/usbl.csv"),
    _in_dive("images/index.csv"),
    Reader(
        "dive nav/dvl.parquet",
        lambda s: s.root / "dvl.parquet",
        lambda w: w / "dive/nav/dvl.parquet",
        _validate,
        examples=15,
        prepare=lambda w: (w / "dive/nav/dvl.csv").unlink(),
    ),
    Reader("correction", lambda s: s.correction, lambda w: w / "correction.yaml", _read_correction),
    Reader("loops", lambda s: s.loops, lambda w: w / "loops.csv", _read_loops),
    Reader("g2o 2D", lambda s: s.g2o, lambda w: w / "graph.g2o", _read_g2o),
    Reader("g2o 3D", lambda s: s.g2o_3d, lambda w: w / "graph3d.g2o", _read_g2o),
    Reader("tide", lambda s: s.tide, lambda w: w / "tide.csv", _read_tide),
    Reader("atmospheric", lambda s: s.atmospheric, lambda w: w / "atmosphere.csv", _read_atmospheric),
    Reader("mission", lambda s: s.mission, lambda w: w / "mission.yaml", _read_mission),
    Reader("ros camera_info", lambda s: s.ros_left, lambda w: w / "left.yaml", _read_ros),
    Reader("opencv calibration", lambda s: s.opencv, lambda w: w / "stereo.yml", _read_opencv),
    Reader("settings", lambda s: s.settings, lambda w: w / "settings.yaml", _read_settings),
    _importer("acfr-raw", "combined.RAW.auv"),
    _importer("pd0", "dvl.pd0", "pd0.yaml"),
    _importer("nmea", "gps.log"),
    _importer("csv", "csv/dvl_log.csv", "csv/mapping.yaml"),
]
#: Examples each reader ran in this session (printed with -s).
RAN: dict[str, int] = {}


@pytest.fixture(scope="module")
def samples(tmp_path_factory: pytest.TempPathFactory):
    s = bad_input.write_samples(tmp_path_factory.mktemp("samples"), seconds=20.0, rate_hz=2.0)
    writers = _load_writers_module()
    dive = bad_input.small_dive(20.0, 2.0)
    logs = s.root / "logs"
    logs.mkdir()
    raw, _ = writers.write_acfr(dive, logs)  # combined.RAW.auv and mission.cfg beside it
    raw.rename(logs / "combined.RAW.auv")
    writers.write_pd0(dive, logs / "dvl.pd0")
    (logs / "pd0.yaml").write_text(
        "origin: {latitude_deg: -14.05, longitude_deg: 121.78}\n", encoding="utf-8"
    )
    writers.write_nmea(dive, logs / "gps.log")
    writers.write_csvs(dive, logs / "csv")
    return s


def _check_lines(text: str, reader: str) -> None:
    lines = text.splitlines()
    assert 1 <= len(lines) <= MAX_LINES, f"{reader}: {len(lines)} lines"
    long = [line for line in lines if len(line) > MAX_LINE]
    assert not long, f"{reader}: a line of {len(long[0])} characters: {long[0][:200]}..."


@pytest.mark.parametrize("reader", READERS, ids=[r.name for r in READERS])
def test_reader_raises_only_its_own_error(reader: Reader, samples, tmp_path_factory) -> None:
    work = tmp_path_factory.mktemp("work")
    shutil.copytree(samples.root, work, dirs_exist_ok=True)
    if reader.prepare is not None:
        reader.prepare(work)
    target = reader.target(work)
    sample = reader.sample(samples).read_bytes()
    RAN[reader.name] = 0
    examples = EXAMPLES or reader.examples

    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        derandomize=EXAMPLES is None,  # the suite's run is repeatable; a long run explores
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(data=mutated(sample))
    def run(data: bytes) -> None:
        RAN[reader.name] += 1
        target.write_bytes(data)
        try:
            found = reader.read(target, work)
        except AuvnavError as err:
            _check_lines(str(err), reader.name)
            return
        if isinstance(found, list):
            for item in found:
                _check_lines(str(item), reader.name)

    run()
    print(f"fuzz {reader.name}: {RAN[reader.name]} examples")
    if os.environ.get("AUVNAV_FUZZ_REPORT"):  # the benchmark run's record: reader, examples
        with open(os.environ["AUVNAV_FUZZ_REPORT"], "a", encoding="utf-8") as out:
            out.write(f"{reader.name}\t{RAN[reader.name]}\n")
    assert RAN[reader.name] >= min(examples, 10)
