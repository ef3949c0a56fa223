"""Tides: prediction from harmonic constituents, harmonic analysis of a gauge record, datum correction.

The tide ``eta(t)`` is the water level above the datum, metres, positive up; depth below the datum is
pressure depth minus ``eta(t)`` (DESIGN section 4). Prediction and analysis both go through UTide
(Codiga 2011, the Python port ``utide``): Greenwich phase lags, exact-time nodal (satellite)
corrections and astronomical arguments, utide's constituent table.

Constituent file
----------------
A small UTF-8 CSV file, for instance the simulator's ``truth/tide.csv``::

    # reference: Honolulu 2010, MATLAB UTide ut_solv (OLS, linci)
    # mean_m: 1.417343
    name,amplitude_m,phase_deg
    M2,0.176922,58.834643
    K1,0.150014,225.806930

- Optional lines ``# key: value`` before the header, each key at most once: ``reference`` (free text:
  where the constants come from) and ``mean_m`` (the mean water level above the datum, Z0, metres;
  0 when absent). Any other comment line is an error.
- The header names the three columns ``name``, ``amplitude_m``, ``phase_deg``, in any order.
- One row per constituent: a name in utide's constituent table (``M2``, ``K1``, ``MSF``, ...; case
  matters, each name once, ``Z0`` is the ``mean_m`` line), the amplitude in metres (>= 0) and the
  Greenwich phase lag in degrees in [0, 360). Blank lines are ignored.

Every problem is an error of one line naming the file and the line.

References
----------
Codiga, D. L. (2011). Unified tidal analysis and prediction using the UTide Matlab functions.
    Technical Report 2011-01, Graduate School of Oceanography, University of Rhode Island.
Pawlowicz, R., Beardsley, B. and Lentz, S. (2002). Classical tidal harmonic analysis including error
    estimates in MATLAB using T_TIDE. Computers and Geosciences 28, 929-937.
"""

from __future__ import annotations

import csv
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import date, datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import utide
from numpy.typing import ArrayLike
from utide._solve import default_opts as _UTIDE_SOLVE_OPTIONS
from utide._ut_constants import constit_index_dict as _UTIDE_INDEX
from utide._ut_constants import ut_constants as _UTIDE_CONSTANTS
from utide.utilities import Bunch

from auvnav.config import quote, read_text
from auvnav.errors import ConfigError, InsufficientDataError
from auvnav.frames import FloatArray

log = logging.getLogger(__name__)

SECONDS_PER_DAY = 86400.0
_UTIDE_EPOCH = "1970-01-01"  # utide takes days since this epoch: t_s / SECONDS_PER_DAY
_POSIX_EPOCH_DATENUM = float(date(1970, 1, 1).toordinal())  # utide's datenum (days since 0000-12-31)
_PREDICT_BLOCK = 20_000  # samples per call to utide.reconstruct: bounds its (samples x 162) arrays
_COLUMNS = ("name", "amplitude_m", "phase_deg")
_MAX_FILE_BYTES = 2**20  # a constituent file is a few hundred bytes: utide's table has 146 names
_COMMENT = re.compile(r"#\s*(\w+)\s*:\s*(.*)$")
_MEAN_NAME = "Z0"
# Options analyse_gauge sets itself, and options whose other values would break the model's meaning.
_RESERVED_OPTIONS = ("epoch", "lat", "verbose")
_FIXED_OPTIONS = {"phase": "Greenwich", "nodal": True}


@dataclass(frozen=True)
class Constituent:
    """One tidal constituent.

    Parameters
    ----------
    name : str
        Name in utide's constituent table (``"M2"``, ``"K1"``, ...), not ``"Z0"`` (the mean).
    amplitude_m : float
        Amplitude, metres, >= 0.
    phase_rad : float
        Greenwich phase lag, radians, in [0, 2 pi).
    """

    name: str
    amplitude_m: float
    phase_rad: float

    def __post_init__(self) -> None:
        if self.name not in _UTIDE_INDEX or self.name == _MEAN_NAME:
            raise ValueError(f"constituent name must be in utide's table, not Z0; found {self.name!r}")
        if not (math.isfinite(self.amplitude_m) and self.amplitude_m >= 0):
            raise ValueError(f"amplitude_m must be finite and >= 0; found {self.amplitude_m!r}")
        if not 0 <= self.phase_rad < 2 * math.pi:
            raise ValueError(f"phase_rad must lie in [0, 2 pi); found {self.phase_rad!r}")


@dataclass(frozen=True)
class TideModel:
    """A harmonic tide model: ``eta(t) = mean_m + sum of constituents`` with nodal corrections.

    Parameters
    ----------
    constituents : tuple of Constituent
        Each name at most once; may be empty (a constant level).
    latitude_rad : float
        Latitude of the place, radians (utide's nodal corrections of some diurnal constituents use it).
    reference : str
        Where the constants come from; one line.
    mean_m : float
        Mean water level above the datum (Z0), metres.
    """

    constituents: tuple[Constituent, ...]
    latitude_rad: float
    reference: str = ""
    mean_m: float = 0.0

    def __post_init__(self) -> None:
        constituents = tuple(self.constituents)
        if not all(isinstance(c, Constituent) for c in constituents):
            raise ValueError("constituents must be Constituent objects")
        names = [c.name for c in constituents]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"constituent names must be unique; found {duplicates} more than once")
        if not -math.pi / 2 <= self.latitude_rad <= math.pi / 2:
            raise ValueError(f"latitude_rad must lie in [-pi/2, pi/2]; found {self.latitude_rad!r}")
        if not math.isfinite(self.mean_m):
            raise ValueError(f"mean_m must be finite; found {self.mean_m!r}")
        if "\n" in self.reference or "\r" in self.reference:
            raise ValueError("reference must be a single line")
        object.__setattr__(self, "constituents", constituents)

    def predict(self, t_s: ArrayLike) -> FloatArray:
        """The tide at times ``t_s``, by ``utide.reconstruct`` with nodal corrections.

        Parameters
        ----------
        t_s : array_like, any shape, seconds since the POSIX epoch, UTC
            Finite times.

        Returns
        -------
        ndarray, shape of ``t_s``, metres, positive up (water level above the datum)
        """
        t = np.asarray(t_s, dtype=float)
        if not np.all(np.isfinite(t)):
            raise ValueError("t_s must be finite")
        eta = np.full(t.size, self.mean_m)
        if t.size == 0 or not self.constituents:
            return eta.reshape(t.shape)
        t_days = t.ravel() / SECONDS_PER_DAY
        coef = self._utide_coef(reftime_days=0.5 * (t_days.min() + t_days.max()))
        for start in range(0, t_days.size, _PREDICT_BLOCK):
            block = slice(start, start + _PREDICT_BLOCK)
            eta[block] = utide.reconstruct(
                t_days[block], coef, epoch=_UTIDE_EPOCH, verbose=False, min_SNR=0, min_PE=0
            ).h
        return eta.reshape(t.shape)

    def _utide_coef(self, reftime_days: float) -> Bunch:
        """The coefficient structure ``utide.reconstruct`` takes (as ``utide.solve`` returns it).

        Greenwich phase and nodal corrections at the exact times (utide's defaults), no trend;
        ``reftime_days`` (days since the POSIX epoch) only anchors utide's bookkeeping.
        """
        lind = np.array([_UTIDE_INDEX[c.name] for c in self.constituents], dtype=int)
        opt = Bunch(
            twodim=False,
            notrend=True,
            nodiagn=True,
            nodsatlint=False,
            nodsatnone=False,
            gwchlint=False,
            gwchnone=False,
            prefilt=[],
        )
        aux = Bunch(
            reftime=reftime_days + _POSIX_EPOCH_DATENUM,
            lat=math.degrees(self.latitude_rad),
            lind=lind,
            frq=np.asarray(_UTIDE_CONSTANTS.const.freq, dtype=float)[lind],
            opt=opt,
        )
        return Bunch(
            name=np.array([c.name for c in self.constituents]),
            A=np.array([c.amplitude_m for c in self.constituents]),
            g=np.degrees([c.phase_rad for c in self.constituents]),
            mean=self.mean_m,
            aux=aux,
        )


def _fail(path: Path, line: int, message: str) -> ConfigError:
    return ConfigError(f"{path}: line {line}: {message}")


def _parse_number(path: Path, line: int, column: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise _fail(path, line, f"{column} {quote(text.strip())} is not a finite number")
    return value


def _check_name(path: Path, line: int, name: str, seen: set[str]) -> None:
    if name == _MEAN_NAME:
        raise _fail(path, line, "Z0 is the mean level: give it as '# mean_m: <metres>'")
    if name not in _UTIDE_INDEX:
        close = [n for n in _UTIDE_INDEX if n.upper() == name.upper()]
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise _fail(path, line, f"unknown constituent {quote(name)}{hint}; not in utide's table")
    if name in seen:
        raise _fail(path, line, f"constituent {name} appears twice")
    seen.add(name)


def read_constituents(path: Path, *, latitude_rad: float) -> TideModel:
    """Read a constituent file (format in the module docstring) into a tide model.

    Parameters
    ----------
    path : Path
        The CSV file.
    latitude_rad : float
        Latitude of the place, radians.

    Raises
    ------
    ConfigError
        One line naming the file, the line and the problem.
    """
    path = Path(path)
    text, problems = read_text(path, str(path), max_bytes=_MAX_FILE_BYTES)
    if text is None:
        raise ConfigError(str(problems[0]))
    lines = text.removeprefix("\ufeff").splitlines()
    meta: dict[str, str] = {}
    header: list[str] | None = None
    constituents: list[Constituent] = []
    seen: set[str] = set()
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        if line.lstrip().startswith("#"):
            if header is not None:
                raise _fail(path, number, "comment lines belong before the header")
            match = _COMMENT.match(line.strip())
            key = match.group(1) if match else None
            if key not in ("reference", "mean_m"):
                raise _fail(path, number, "comment lines must be '# reference: ...' or '# mean_m: ...'")
            if key in meta:
                raise _fail(path, number, f"{key} given twice")
            meta[key] = match.group(2).strip()
            if key == "mean_m":
                _parse_number(path, number, "mean_m", meta[key])
            continue
        try:
            fields = [field.strip() for field in next(csv.reader([line]))]
        except csv.Error as err:
            raise _fail(path, number, f"not a CSV line ({err})") from None
        if header is None:
            missing = [c for c in _COLUMNS if c not in fields]
            unknown = [f for f in fields if f not in _COLUMNS]
            if missing or unknown or len(fields) != len(_COLUMNS):
                raise _fail(
                    path,
                    number,
                    f"the header must name the columns {','.join(_COLUMNS)}; found {quote(line.strip())}"
                    + (f" (missing {', '.join(missing)})" if missing else ""),
                )
            header = fields
            continue
        if len(fields) != len(header):
            raise _fail(path, number, f"expected {len(header)} fields, found {len(fields)}")
        row = dict(zip(header, fields, strict=True))
        _check_name(path, number, row["name"], seen)
        amplitude_m = _parse_number(path, number, "amplitude_m", row["amplitude_m"])
        if amplitude_m < 0:
            raise _fail(path, number, f"amplitude_m {amplitude_m!r} is negative")
        phase_deg = _parse_number(path, number, "phase_deg", row["phase_deg"])
        if not 0 <= phase_deg < 360:
            raise _fail(path, number, f"phase_deg {phase_deg!r} is outside [0, 360)")
        constituents.append(Constituent(row["name"], amplitude_m, math.radians(phase_deg) % (2 * math.pi)))
    if header is None:
        raise ConfigError(f"{path}: no header line {','.join(_COLUMNS)}")
    return TideModel(
        constituents=tuple(constituents),
        latitude_rad=latitude_rad,
        reference=meta.get("reference", ""),
        mean_m=float(meta.get("mean_m", 0.0)),
    )


def write_constituents(model: TideModel, path: Path) -> None:
    """Write a tide model as a constituent file (format in the module docstring).

    The latitude is not written: :func:`read_constituents` takes it from the dive. Numbers are written
    with full precision, so reading the file back gives the same model to the last bit or so.
    """
    lines = []
    if model.reference:
        lines.append(f"# reference: {model.reference}")
    lines.append(f"# mean_m: {model.mean_m!r}")
    lines.append(",".join(_COLUMNS))
    for c in model.constituents:
        phase_deg = math.degrees(c.phase_rad) % 360.0
        lines.append(f"{c.name},{c.amplitude_m!r},{phase_deg!r}")
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _utc(t_s: float) -> str:
    return datetime.fromtimestamp(round(t_s), tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def analyse_gauge(t_s: ArrayLike, eta_m: ArrayLike, latitude_rad: float, **utide_options: Any) -> TideModel:
    """Harmonic analysis of a tide gauge record by ``utide.solve``.

    utide's defaults are those of the MATLAB UTide ``ut_solv`` runs in the reference data: automatic
    constituent selection (Rayleigh criterion 1), ordinary least squares, linearised confidence
    intervals, a linear trend, nodal corrections and Greenwich phase lags. A fitted trend is logged
    and not kept: the model is periodic about ``mean_m``, the fitted level at the record's mid-time.

    Parameters
    ----------
    t_s : array_like, shape (N,), seconds since the POSIX epoch, UTC
        Sample times, finite.
    eta_m : array_like, shape (N,), metres, positive up
        Water level above the gauge datum. NaN marks a gap (counted in a warning).
    latitude_rad : float
        Latitude of the gauge, radians.
    **utide_options
        Options of ``utide.solve`` (``constit``, ``method``, ``conf_int``, ``trend``, ``infer``,
        ``Rayleigh_min``, ...); ``infer`` may be a plain mapping. ``epoch``, ``lat`` and ``verbose``
        are set here; ``phase`` must stay ``"Greenwich"`` and ``nodal`` ``True``.

    Returns
    -------
    TideModel
        Constituents in utide's order (decreasing energy), ``mean_m`` and a reference that says
        what was analysed.

    Raises
    ------
    InsufficientDataError
        Fewer than three finite samples, or a record too short to resolve any constituent.
    """
    t = np.asarray(t_s, dtype=float)
    eta = np.asarray(eta_m, dtype=float)
    if t.ndim != 1 or t.shape != eta.shape:
        raise ValueError(f"t_s and eta_m must be 1-D and match; found {t.shape} and {eta.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_s must be finite")
    if not -math.pi / 2 <= latitude_rad <= math.pi / 2:
        raise ValueError(f"latitude_rad must lie in [-pi/2, pi/2]; found {latitude_rad!r}")
    options = _utide_solve_options(utide_options)
    good = np.isfinite(eta)
    if np.count_nonzero(good) < 3:
        raise InsufficientDataError(
            f"tide analysis needs at least 3 finite samples; found {np.count_nonzero(good)}"
        )
    if not np.all(good):
        log.warning("tide analysis: %d of %d samples are NaN (gaps)", np.count_nonzero(~good), t.size)
    coef = utide.solve(
        t / SECONDS_PER_DAY,
        eta,
        lat=math.degrees(latitude_rad),
        epoch=_UTIDE_EPOCH,
        verbose=False,
        **options,
    )
    span_h = float(np.ptp(t[good])) / 3600.0
    if len(coef.name) == 0:
        raise InsufficientDataError(
            f"a record of {span_h:.1f} h resolves no tidal constituent (Rayleigh criterion); "
            "M2 needs about 13 h"
        )
    if "slope" in coef:
        log.info(
            "tide analysis: linear trend %.3g m/day fitted and not kept in the model",
            coef.slope,
        )
    constituents = tuple(
        Constituent(str(name), float(a), math.radians(float(g)) % (2 * math.pi))
        for name, a, g in zip(coef.name, coef.A, coef.g, strict=True)
    )
    reference = (
        f"utide {utide.__version__} solve of {np.count_nonzero(good)} samples, "
        f"{_utc(t[good].min())} to {_utc(t[good].max())}"
    )
    return TideModel(constituents, latitude_rad, reference=reference, mean_m=float(coef.mean))


def _utide_solve_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """Check ``analyse_gauge``'s utide options; a plain ``infer`` mapping becomes utide's Bunch."""
    for key, value in options.items():
        if key in _RESERVED_OPTIONS:
            raise TypeError(f"analyse_gauge sets utide's {key!r} option itself")
        if key not in _UTIDE_SOLVE_OPTIONS:
            raise TypeError(f"unknown utide.solve option {key!r}")
        if key in _FIXED_OPTIONS and value != _FIXED_OPTIONS[key]:
            raise ValueError(f"utide option {key!r} must be {_FIXED_OPTIONS[key]!r}; found {value!r}")
    checked = dict(options)
    if isinstance(checked.get("infer"), Mapping) and not isinstance(checked["infer"], Bunch):
        checked["infer"] = Bunch(checked["infer"])
    return checked


def depth_below_datum(depth_m: ArrayLike, t_s: ArrayLike, tide: TideModel) -> FloatArray:
    """Depth below the datum: pressure depth minus the tide (DESIGN section 4).

    Parameters
    ----------
    depth_m : array_like, shape (N,), metres, positive down
        Depth below the sea surface (from pressure).
    t_s : array_like, shape (N,), seconds since the POSIX epoch, UTC
    tide : TideModel
        The tide above the datum.

    Returns
    -------
    ndarray, shape (N,), metres, positive down, below the datum
    """
    depth = np.asarray(depth_m, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if depth.shape != t.shape:
        raise ValueError(f"depth_m and t_s must match; found {depth.shape} and {t.shape}")
    return depth - tide.predict(t)
