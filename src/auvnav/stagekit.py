"""What a stage is made of: its settings, its inputs, how it runs (DESIGN sections 2 and 6).

Each domain package has one ``stage.py`` that declares a :class:`Stage`: the folder of its products
(``products/<name>``), the stages whose products it reads, a frozen dataclass of :class:`settings
<setting>` (each with the help text and command-line flag it gets, declared once), which files its
result depends on, when the dive's data does not allow it, and a ``run`` that computes with the
domain's pure functions and writes its products into the folder it is given.
:mod:`auvnav.pipeline` orders the stages, keys them, skips what is up to date and swaps each
stage's products in atomically; the ``auvnav`` command builds each stage's command-line options
from its settings.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol

from auvnav.config import quote
from auvnav.errors import AuvnavError, ConfigError
from auvnav.executor import Executor

Progress = Callable[[str, int, int], None]


class StageSkipped(AuvnavError):
    """Raised by a stage's ``run`` when the dive's data cannot give its products; the message says why.

    The pipeline records the stage as skipped with that reason (no products), so an unchanged rerun
    does not try again.
    """


def setting(
    default: Any,
    help: str,
    *,
    flag: str | None = None,
    minimum: float | None = None,
    maximum: float | None = None,
) -> Any:
    """A stage setting: its default, help text, command-line flag (``--name-with-dashes`` by default)
    and bounds, declared once for the stage, its command and ``auvnav process``."""
    meta = {"help": help, "flag": flag, "minimum": minimum, "maximum": maximum}
    if isinstance(default, (list, dict, set)):
        raise TypeError("setting defaults must be immutable (use a tuple)")
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class NoSettings:
    """A stage without settings."""


@dataclass(frozen=True)
class StageContext:
    """What a stage's ``run`` gets besides its settings.

    Parameters
    ----------
    dive : Path
        The dive folder.
    executor : callable
        Gives the executor for per-item work (made on first use; the pipeline closes it).
    progress : callable(what, done, total), optional
    allow_outside : bool
        Files the dive names outside its folder may be read (``--allow-outside``; each is said):
        give it to :func:`~auvnav.dive.read_dive`.
    """

    dive: Path
    executor: Callable[[], Executor]
    progress: Progress | None = None
    allow_outside: bool = False

    def tick(self, what: str, done: int, total: int) -> None:
        if self.progress is not None:
            self.progress(what, done, total)


class RunFn(Protocol):
    def __call__(self, ctx: StageContext, settings: Any, out: Path) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Stage:
    """One stage of the pipeline.

    Parameters
    ----------
    name : str
        Its products' folder (``products/<name>``) and its name in ``auvnav process``.
    title : str
        What it does, in a phrase (``--dry-run``, ``--help``).
    after : tuple of str
        Stages whose products it may read: they run before it.
    settings : type
        A frozen dataclass of :func:`setting` fields.
    inputs : callable(dive, settings) -> dict of str to Path
        Every file the result depends on, by a label (the path inside the dive, or the setting's
        name for a file outside it); a missing file is left out.
    unavailable : callable(dive, settings) -> str or None
        Why the dive's data does not allow the stage (a cheap check before any work), or None.
    run : callable(ctx, settings, out) -> dict
        Computes and writes the products into ``out``; returns the summary.
    describe : callable(summary) -> str
        The human account of a summary.
    uses_executor : bool
        The stage spreads per-item work over the executor.
    """

    name: str
    title: str
    after: tuple[str, ...]
    settings: type
    inputs: Callable[[Path, Any], dict[str, Path]]
    unavailable: Callable[[Path, Any], str | None]
    run: RunFn
    describe: Callable[[dict[str, Any]], str]
    uses_executor: bool = False


# ---------------------------------------------------------------------------------------------
# Settings from mappings and command-line values
# ---------------------------------------------------------------------------------------------


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    """``X | None`` -> (X, True); anything else -> (tp, False)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
    return tp, False


def field_types(cls: type) -> dict[str, Any]:
    """The settings class's field types, resolved."""
    return typing.get_type_hints(cls)


def _coerce(name: str, tp: Any, value: Any, meta: Mapping[str, Any], base: Path | None) -> Any:
    """``value`` as the field's type (from YAML or a ``--set`` string), checked; else ConfigError."""
    kind, optional = _unwrap_optional(tp)
    if value is None:
        if optional:
            return None
        raise ConfigError(f"{name}: must be given (found null)")
    origin = typing.get_origin(kind)
    if origin is Literal:
        choices = typing.get_args(kind)
        if value not in choices:
            raise ConfigError(f"{name}: expected one of {', '.join(map(str, choices))}; found {quote(value)}")
        return value
    if origin is tuple:
        (inner,) = (a for a in typing.get_args(kind) if a is not Ellipsis)
        items = value if isinstance(value, (list, tuple)) else [value]
        return tuple(_coerce(name, inner, v, meta, base) for v in items)
    if kind is bool:
        if isinstance(value, bool):
            return value
        text = str(value).strip().lower()
        if text in ("true", "yes", "on", "1"):
            return True
        if text in ("false", "no", "off", "0"):
            return False
        raise ConfigError(f"{name}: expected true or false; found {quote(value)}")
    if kind in (int, float):
        if isinstance(value, bool):
            raise ConfigError(f"{name}: expected a number; found {quote(value)}")
        try:
            number = kind(value) if kind is float or isinstance(value, int) else int(str(value))
        except (TypeError, ValueError):
            raise ConfigError(
                f"{name}: expected {'an integer' if kind is int else 'a number'}; found {quote(value)}"
            ) from None
        if number != number or number in (float("inf"), float("-inf")):
            raise ConfigError(f"{name}: must be finite; found {quote(value)}")
        lo, hi = meta.get("minimum"), meta.get("maximum")
        if (lo is not None and number < lo) or (hi is not None and number > hi):
            bounds = f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
            raise ConfigError(f"{name}: must be in {bounds}; found {number:g}")
        return number
    if kind is Path:
        if not isinstance(value, (str, Path)) or not str(value):
            raise ConfigError(f"{name}: expected a file path; found {quote(value)}")
        path = Path(value)
        path = base / path if base is not None and not path.is_absolute() else path
        if path.exists() and not (path.is_file() or path.is_dir()):  # a named pipe would block its reader
            raise ConfigError(f"{name}: {path}: not a regular file")
        return path
    if kind is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}: expected text; found {quote(value)}")
        return value
    raise TypeError(f"{name}: unsupported setting type {tp!r}")


def make_settings(cls: type, values: Mapping[str, Any], where: str, *, base: Path | None = None) -> Any:
    """Settings from a mapping of field names to values (YAML, ``--set``, options); strict.

    A relative file path is taken relative to ``base`` when given (a settings file's folder).

    Raises
    ------
    ConfigError
        An unknown key or a bad value, naming ``where`` (a file or ``--set``) and the key.
    """
    types_ = field_types(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in values.items():
        if key not in fields:
            known = ", ".join(fields) or "none"
            raise ConfigError(f"{where}: unknown setting {quote(key)} (settings: {known})")
        kwargs[key] = _coerce(f"{where}: {key}", types_[key], value, fields[key].metadata, base)
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise ConfigError(f"{where}: {err}") from err


def settings_mapping(settings: Any) -> dict[str, Any]:
    """Plain data of a settings object (paths as text), for records and messages."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if isinstance(value, Path):
            value = str(value)
        elif isinstance(value, tuple):
            value = [str(v) if isinstance(v, Path) else v for v in value]
        out[f.name] = value
    return out
