"""Typed time series read from and written to tables, with strict validation.

A stream is a frozen dataclass of equal-length numpy arrays (SI units, radians) that declares how its
fields map to file columns (with the file's units). :func:`read_table` reads a ``.csv`` or ``.parquet``
file and reports every problem (file, row, column) instead of guessing; :meth:`Stream.to_frame` and
:func:`write_table` give the file form back. Rows are 1-based data rows (the CSV header is not counted).
"""

from __future__ import annotations

import codecs
import csv
import dataclasses
import json
import logging
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from auvnav.config import cut, quote
from auvnav.errors import DiveFormatError, OutputExistsError, Problem

log = logging.getLogger(__name__)

Kind = Literal["float", "int", "bool", "str"]
S = TypeVar("S", bound="Stream")

_UMASK = os.umask(0o022)
os.umask(_UMASK)

#: At most this many rows are named for one kind of problem in one column; the rest are counted.
MAX_ROWS_NAMED = 5
#: Longest line of a CSV table, bytes (a stream's row is under 100 bytes, a loop closure's under 1000).
MAX_LINE_BYTES = 2**16
#: A Parquet file over 256 MiB uncompressed may expand at most this many times its size.
MAX_PARQUET_EXPANSION = 100
_BLOCK_BYTES = 2**20
#: Largest integer a table's integer column holds exactly (as read through a float).
MAX_EXACT_INT = 2**53


@dataclass(frozen=True)
class Field:
    """How one stream attribute is stored in a file.

    Parameters
    ----------
    name : str
        Attribute name on the stream (SI units in the name).
    columns : tuple of str
        File columns (file units in the names); several columns make an (N, k) array.
    scale : float
        Multiply file values by this to get the attribute's SI value (``np.pi / 180`` for degrees).
    kind : {"float", "bool", "str"}
    required : bool
        False for columns that may be absent; the attribute is then None.
    check : callable, optional
        ``check(values_in_file_units) -> message or None``, a plausibility test on the whole column.
    """

    name: str
    columns: tuple[str, ...]
    scale: float = 1.0
    kind: Kind = "float"
    required: bool = True
    check: Callable[[np.ndarray], str | None] | None = None


def within(lo: float, hi: float, unit: str, hint: str = "") -> Callable[[np.ndarray], str | None]:
    """A plausibility check: every value in [lo, hi] (file units)."""

    def check(v: np.ndarray) -> str | None:
        bad = (v < lo) | (v > hi)
        if not bad.any():
            return None
        row = int(np.flatnonzero(bad)[0]) + 1
        return (
            f"{int(bad.sum())} value(s) outside [{lo:g}, {hi:g}] {unit}, first {v[row - 1]:g} "
            f"at row {row}{hint}"
        )

    return check


def looks_like_radians(v: np.ndarray) -> str | None:
    """Flag a degree column that holds radians: every value within +-2 pi, and a wrap-around jump.

    A heading in radians wraps by nearly 2 pi between consecutive samples whenever the vehicle turns
    through the wrap point (south for (-pi, pi], north for [0, 2 pi)), which every dive with turns does.
    A wrap jumps by at least 2 pi less one sample's turn (> 6.1 even logged at 1 Hz); degrees that stay
    within +-6.3 of north (a northbound transect) do not jump by 5.5 between samples.
    """
    finite = v[np.isfinite(v)]
    if finite.size < 3 or np.abs(finite).max() > 2 * np.pi + 1e-9:
        return None
    jumps = np.abs(np.diff(finite))
    if not (jumps > 5.5).any():
        return None
    return (
        f"values span {finite.min():.3f} to {finite.max():.3f}, all within +-2 pi, and wrap by "
        f"{jumps.max():.3f} between rows: these are radians, the column declares degrees"
    )


@dataclass(frozen=True)
class Stream:
    """Base of every typed stream: equal-length arrays; the first field is the time (strictly increasing
    unless ``TIME_ORDERED`` is false)."""

    FIELDS: ClassVar[tuple[Field, ...]]
    FILE: ClassVar[str]
    #: False for tables whose rows are not a time series (loop closures): no ordering is required.
    TIME_ORDERED: ClassVar[bool] = True

    def __post_init__(self) -> None:
        n = None
        for f in self.FIELDS:
            value = getattr(self, f.name)
            if value is None:
                if f.required:
                    raise ValueError(f"{type(self).__name__}.{f.name} is required")
                continue
            arr = np.asarray(value)
            want = (len(f.columns),) if len(f.columns) > 1 else ()
            if arr.ndim != 1 + len(want) or arr.shape[1:] != want:
                raise ValueError(
                    f"{type(self).__name__}.{f.name} must have shape (N{', ' + str(want[0]) if want else ''}); "
                    f"found {arr.shape}"
                )
            n = arr.shape[0] if n is None else n
            if arr.shape[0] != n:
                raise ValueError(
                    f"{type(self).__name__} fields must share one length; found {arr.shape[0]} and {n}"
                )
        t = np.asarray(getattr(self, self.FIELDS[0].name))
        if self.TIME_ORDERED and t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError(f"{type(self).__name__}.{self.FIELDS[0].name} must be strictly increasing")

    def __len__(self) -> int:
        return len(getattr(self, self.FIELDS[0].name))

    @classmethod
    def from_columns(cls: type[S], values: dict[str, NDArray]) -> S:
        """Build from file-unit columns (already validated), converting to SI."""
        kwargs = {}
        for f in cls.FIELDS:
            if not all(c in values for c in f.columns):
                kwargs[f.name] = None
                continue
            cols = [values[c] for c in f.columns]
            if f.kind == "float":
                arr = np.stack([np.asarray(c, dtype=float) * f.scale for c in cols], -1)
            elif f.kind == "int":
                arr = np.stack([np.asarray(c, dtype=np.int64) for c in cols], -1)
            elif f.kind == "bool":
                arr = np.stack([np.asarray(c, dtype=bool) for c in cols], -1)
            else:
                arr = np.stack([np.asarray(c, dtype=str) for c in cols], -1)
            kwargs[f.name] = arr if len(f.columns) > 1 else arr[:, 0]
        return cls(**kwargs)

    def to_frame(self) -> pd.DataFrame:
        """The file form: one column per file column, in file units."""
        data: dict[str, NDArray] = {}
        for f in self.FIELDS:
            value = getattr(self, f.name)
            if value is None:
                continue
            arr = np.asarray(value)
            arr = arr.reshape(len(arr), len(f.columns))
            for k, c in enumerate(f.columns):
                col = arr[:, k]
                data[c] = col / f.scale if f.kind == "float" else col
        return pd.DataFrame(data)

    def select(self: S, mask: NDArray[np.bool_]) -> S:
        """A new stream with the rows where ``mask`` is true."""
        return dataclasses.replace(
            self,
            **{
                f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[mask]
                for f in self.FIELDS
            },
        )


def _scan_text(path: Path, display: str) -> list[Problem]:
    """Check a CSV file block by block before it is parsed: text (no NUL byte, UTF-8) and no line
    longer than :data:`MAX_LINE_BYTES`, so that neither a binary file nor one huge field is ever
    held in memory whole."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    offset = 0  # bytes read before this block
    line_start = 0  # offset of the current line's first byte
    line_no = 1
    with path.open("rb") as fh:
        while block := fh.read(_BLOCK_BYTES):
            if b"\x00" in block:
                return [Problem(display, "not a CSV text file (binary content)")]
            try:
                decoder.decode(block)
            except UnicodeDecodeError as err:
                return [Problem(display, f"not a CSV text file (not UTF-8 at byte {offset + err.start})")]
            ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10) + offset
            starts = np.concatenate([[line_start], ends[:-1] + 1]) if ends.size else np.array([line_start])
            lengths = (ends - starts[: ends.size]) if ends.size else np.zeros(0, dtype=np.int64)
            too_long = np.flatnonzero(lengths > MAX_LINE_BYTES)
            if too_long.size:
                k = int(too_long[0])
                return [_long_line(display, line_no + k)]
            if ends.size:
                line_no += ends.size
                line_start = int(ends[-1]) + 1
            offset += len(block)
            if offset - line_start > MAX_LINE_BYTES:
                return [_long_line(display, line_no)]
        try:
            decoder.decode(b"", final=True)
        except UnicodeDecodeError:
            return [Problem(display, f"not a CSV text file (not UTF-8 at byte {offset})")]
    return []


def _long_line(display: str, line_no: int) -> Problem:
    return Problem(
        display,
        f"line {line_no} is longer than the {MAX_LINE_BYTES} bytes a table's line may have "
        "(a broken line, or a field that is not a value?)",
    )


def _duplicate_columns(path: Path) -> list[str]:
    """Column names the CSV header gives more than once (pandas would rename them ``x.1``)."""
    with path.open("r", encoding="utf-8-sig", newline="") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                names = [c.strip() for c in next(csv.reader([line.split("#")[0]]), [])]
                return sorted({c for c in names if names.count(c) > 1})
    return []


def _read_parquet(path: Path, display: str) -> tuple[pd.DataFrame | None, list[Problem]]:
    """A Parquet file as a frame, refusing one that would decompress to more than
    :data:`MAX_PARQUET_EXPANSION` times its size (and over 256 MiB)."""
    import pyarrow.parquet as pq

    try:
        meta = pq.ParquetFile(path).metadata
        names = meta.schema.names
        dup = sorted({c for c in names if names.count(c) > 1})
        if dup:
            return None, [Problem(display, f"column {quote(dup[0])} appears twice (one column per name)")]
        size = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
        if size > 2**28 and size > MAX_PARQUET_EXPANSION * max(path.stat().st_size, 1):
            return None, [
                Problem(display, f"decompresses to {size} bytes from {path.stat().st_size}: not read")
            ]
        return pd.read_parquet(path), []
    except MemoryError:
        return None, [Problem(display, "not a readable Parquet file (too large to read)")]
    except Exception as err:  # pyarrow raises many kinds (ArrowInvalid, OSError, TypeError, ...)
        return None, [Problem(display, f"not a readable Parquet file ({_first_line(err)})")]


def _first_line(err: BaseException) -> str:
    text = str(err).strip()
    return cut(text.splitlines()[0]) if text else type(err).__name__


def _read_raw(path: Path, display: str) -> tuple[pd.DataFrame | None, list[Problem]]:
    """Read a CSV or Parquet file as strings/numbers without interpretation."""
    suffix = path.suffix.lower()
    if not path.is_file():
        what = "a folder" if path.is_dir() else "not found" if not path.exists() else "not a regular file"
        return None, [Problem(display, f"not a table file ({what})" if what != "not found" else what)]
    if suffix == ".parquet":
        frame, problems = _read_parquet(path, display)
        if frame is None:
            return None, problems
    else:
        try:
            problems = _scan_text(path, display)
            if problems:
                return None, problems
            dup = _duplicate_columns(path)
            if dup:
                return None, [Problem(display, f"column {quote(dup[0])} appears twice (one column per name)")]
            frame = pd.read_csv(path, comment="#", skipinitialspace=True, dtype=str, keep_default_na=False)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError, OSError, csv.Error) as err:
            return None, [Problem(display, f"not a readable CSV file ({_first_line(err)})")]
    frame.columns = [str(c).strip() for c in frame.columns]
    dup = sorted({c for c in frame.columns if list(frame.columns).count(c) > 1})
    if dup:
        return None, [Problem(display, f"column {quote(dup[0])} appears twice (one column per name)")]
    return frame, []


def flag_rows(
    mask: NDArray[np.bool_], display: str, column: str | None, describe: Callable[[int], str], more: str
) -> list[Problem]:
    """One problem for the flagged rows (1-based): the first row's, with the count and the next few
    rows of the rest, so that one kind of problem in one column is one line however many rows have
    it (``more`` names the kind in the plural)."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    message = describe(int(idx[0]) + 1)
    if idx.size > 1:
        named = ", ".join(str(int(i) + 1) for i in idx[1:MAX_ROWS_NAMED])
        rest = f" and {idx.size - MAX_ROWS_NAMED} more" if idx.size > MAX_ROWS_NAMED else ""
        message += f" (and {idx.size - 1} more {more}: rows {named}{rest})"
    return [Problem(display, message, int(idx[0]) + 1, column)]


def _parse_column(series: pd.Series, kind: Kind, display: str, column: str) -> tuple[NDArray, list[Problem]]:
    """Parse one column; name the rows that are empty, not numbers, NaN, not integers or not booleans."""
    if kind == "str":
        values = series.astype(str).str.strip().to_numpy()
        return values, flag_rows(values == "", display, column, lambda r: "empty value", "empty values")
    if kind == "bool":
        text = series.astype(str).str.strip().str.lower()
        mapping = {"1": True, "0": False, "true": True, "false": False, "1.0": True, "0.0": False}
        bad = ~text.isin(list(mapping)).to_numpy()
        problems = flag_rows(
            bad,
            display,
            column,
            lambda r: f"not a boolean ({quote(series.iloc[r - 1])}; use 1/0)",
            "non-boolean values",
        )
        return text.isin([k for k, v in mapping.items() if v]).to_numpy(dtype=bool), problems
    if series.dtype.kind in "fiub":
        values = series.to_numpy(dtype=float)
        bad_number = np.zeros(len(values), dtype=bool)
    else:
        text = series.astype(str).str.strip()
        values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        is_nan_text = text.str.lower().isin(["nan", "", "na", "null", "none"]).to_numpy()
        bad_number = np.isnan(values) & ~is_nan_text
    non_finite = ~np.isfinite(values) & ~bad_number
    problems = flag_rows(
        bad_number,
        display,
        column,
        lambda r: f"not a number ({quote(series.iloc[r - 1])})",
        "values that are not numbers",
    )
    problems += flag_rows(
        non_finite, display, column, lambda r: "NaN or infinite value", "NaN or infinite values"
    )
    if kind == "int":
        fractional = np.isfinite(values) & (values != np.round(values))
        problems += flag_rows(
            fractional, display, column, lambda r: f"not an integer ({values[r - 1]!r})", "non-integers"
        )
        huge = np.isfinite(values) & ~fractional & (np.abs(values) > MAX_EXACT_INT)
        problems += flag_rows(
            huge, display, column, lambda r: f"integer out of range ({values[r - 1]:g})", "huge integers"
        )
    return values, problems


def _check_time(t: NDArray, display: str, column: str) -> list[Problem]:
    earlier = np.concatenate([[False], np.diff(t) < 0])
    repeated = np.concatenate([[False], np.diff(t) == 0])
    return flag_rows(
        earlier,
        display,
        column,
        lambda r: f"timestamp out of order ({t[r - 1]:.6f} after {t[r - 2]:.6f})",
        "timestamps out of order",
    ) + flag_rows(
        repeated, display, column, lambda r: f"duplicate timestamp {t[r - 1]:.6f}", "duplicate timestamps"
    )


#: A step between samples longer than this many of the stream's own median sample periods is a gap:
#: relative to each stream's rate, so a log sampled every 8 s is not a gap at every sample.
GAP_PERIODS = 5.0


def find_gaps(t_s: NDArray) -> tuple[NDArray[np.intp], float]:
    """The gaps of increasing sample times: the indices ``i`` at which ``t_s[i + 1] - t_s[i]`` exceeds
    :data:`GAP_PERIODS` median periods, and the median period (none and 0 with fewer than two times)."""
    steps = np.diff(np.asarray(t_s, dtype=float))
    period = float(np.median(steps)) if steps.size else 0.0
    if period <= 0:
        return np.zeros(0, dtype=np.intp), period
    return np.flatnonzero(steps > GAP_PERIODS * period), period


def read_table(
    path: Path, fields: tuple[Field, ...], display: str | None = None, *, time_ordered: bool = True
) -> tuple[dict[str, NDArray], list[Problem], list[str]]:
    """Read and check a table against its fields.

    With ``time_ordered`` the first field is the time and must be strictly increasing.

    Returns
    -------
    values : dict
        File-unit columns by name (only when there are no problems; else empty).
    problems : list of Problem
        Everything wrong, one entry per file/row/column.
    warnings : list of str
        Things worth saying that are not errors (unknown columns).
    """
    display = display or str(path)
    frame, problems = _read_raw(path, display)
    if frame is None:
        return {}, problems, []
    known = {c for f in fields for c in f.columns}
    unknown = [c for c in frame.columns if c not in known]
    warnings = []
    names = ", ".join(quote(c) for c in unknown[:MAX_ROWS_NAMED])
    if len(unknown) > MAX_ROWS_NAMED:
        names += f" and {len(unknown) - MAX_ROWS_NAMED} more"
    if unknown:
        warnings.append(f"{display}: unknown column{'s' if len(unknown) > 1 else ''} {names} ignored")
    for f in fields:
        for c in f.columns:
            if f.required and c not in frame.columns:
                hint = f" (the file has {names} instead?)" if unknown else ""
                problems.append(Problem(display, f"missing required column{hint}", None, c))
    if problems:
        return {}, problems, []
    if len(frame) == 0:
        return {}, [Problem(display, "no data rows")], []
    values: dict[str, NDArray] = {}
    for f in fields:
        for c in f.columns:
            if c not in frame.columns:
                continue
            values[c], col_problems = _parse_column(frame[c], f.kind, display, c)
            problems += col_problems
            if f.check is not None and not col_problems:
                message = f.check(values[c])
                if message:
                    problems.append(Problem(display, message, None, c))
    time_col = fields[0].columns[0]
    if time_ordered and time_col in values and not any(p.column == time_col for p in problems):
        problems += _check_time(values[time_col], display, time_col)
    return (values, problems, warnings) if not problems else ({}, problems, [])


def read_stream(cls: type[S], path: Path, display: str | None = None) -> S:
    """Read one stream file, raising :class:`DiveFormatError` with every problem found."""
    values, problems, warnings = read_table(path, cls.FIELDS, display, time_ordered=cls.TIME_ORDERED)
    for w in warnings:
        log.warning(w)
    if problems:
        raise DiveFormatError(problems)
    return cls.from_columns(values)


def ensure_writable(path: Path, *, overwrite: bool) -> Path:
    """Check an output path before any work: an existing file is an error unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists (use --overwrite to replace it)")
    return path


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Write a file through a temporary sibling and a rename, so no half-written file is left."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the mode open() would
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(data: Any, path: Path) -> None:
    """Write a summary as indented JSON (numpy scalars as floats), atomically."""
    text = json.dumps(data, indent=2, default=float) + "\n"
    atomic_write(Path(path), lambda p: p.write_text(text, encoding="utf-8"))


def write_table(frame: pd.DataFrame, path: Path) -> None:
    """Write a table as CSV (shortest round-trip floats) or Parquet, by the file's suffix; atomically."""
    if path.suffix.lower() == ".parquet":
        atomic_write(path, lambda p: frame.to_parquet(p, index=False))
    else:
        atomic_write(path, lambda p: frame.to_csv(p, index=False))


def write_stream(stream: Stream, path: Path) -> None:
    """Write a stream in file units, CSV or Parquet by suffix."""
    write_table(stream.to_frame(), path)
