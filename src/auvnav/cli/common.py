"""What every ``auvnav`` command shares: the application, common options, logging, output, progress
bars, and the command of a pipeline stage built from its settings (declared once, beside them)."""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import inspect
import json
import logging
import sys
import typing
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from auvnav.stagekit import Progress, Stage, field_types, make_settings

app = typer.Typer(
    name="auvnav",
    help="Consistent navigation, compass and depth repair, and 3D reconstructions for survey AUVs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

# Options every command shares (DESIGN section 7).
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the machine-readable summary.")]
VerboseOpt = Annotated[int, typer.Option("-v", "--verbose", count=True, help="More log output.")]
QuietOpt = Annotated[bool, typer.Option("-q", "--quiet", help="Only warnings and errors.")]
OverwriteOpt = Annotated[bool, typer.Option("--overwrite", help="Replace existing outputs.")]
DiveArg = Annotated[Path, typer.Argument(metavar="DIVE", help="A dive folder (format auvnav-dive/1).")]
AllowOutsideOpt = Annotated[
    bool,
    typer.Option(
        "--allow-outside",
        help="Read files the dive names outside its folder (vehicle, calibration, links); each one is said.",
    ),
]
WorkersOpt = Annotated[
    int | None, typer.Option("--workers", min=1, help="Local processes for per-image work [every core].")
]
SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        metavar="ADDRESS",
        help="Spread per-image work over a Dask cluster: its scheduler's address, or local:N to start N workers here.",
    ),
]

log = logging.getLogger("auvnav")


def setup_logging(verbose: int = 0, quiet: bool = False) -> None:
    """Log to stderr: warnings always, info by default, debug with -v."""
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True)


def emit(summary: dict[str, Any], human: str, *, as_json: bool) -> None:
    """Print a command's result: JSON (``--json``) or the human summary."""
    if as_json:
        typer.echo(json.dumps(summary, indent=2, default=float))
    else:
        typer.echo(human)


@contextlib.contextmanager
def progress_bars(silent: bool) -> Iterator[Progress | None]:
    """A ``progress(what, done, total)`` that draws one bar per ``what`` on stderr (None when silent or
    when stderr is not a terminal: a log file gets the lines, not the bars)."""
    if silent or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn("{task.description:9}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, transient=True, console=Console(stderr=True)) as bar:
        tasks: dict[str, Any] = {}

        def progress(what: str, done: int, total: int) -> None:
            if what not in tasks:
                tasks[what] = bar.add_task(what, total=total)
            bar.update(tasks[what], completed=done, total=total)

        yield progress


# ---------------------------------------------------------------------------------------------
# Stage settings as command-line options
# ---------------------------------------------------------------------------------------------


def flag_of(f: dataclasses.Field) -> str:
    """A setting's command-line flag: its declared one, or ``--name-with-dashes``."""
    return f.metadata.get("flag") or "--" + f.name.replace("_", "-")


def setting_parameters(settings_cls: type) -> list[inspect.Parameter]:
    """Typer parameters, one per field of a stage's settings (help, flag and bounds as declared)."""
    hints = field_types(settings_cls)
    params = []
    for f in dataclasses.fields(settings_cls):
        meta = f.metadata
        flag = flag_of(f)
        tp = hints[f.name]
        optional = type(None) in typing.get_args(tp)
        base = next((a for a in typing.get_args(tp) if a is not type(None)), tp) if optional else tp
        info: dict[str, Any] = {"help": meta.get("help", "")}
        if meta.get("minimum") is not None and base in (int, float):
            info["min"] = meta["minimum"]
        if meta.get("maximum") is not None and base in (int, float):
            info["max"] = meta["maximum"]
        default = f.default
        if base is bool:
            decls = flag if default is False else f"{flag}/--no-{flag[2:]}"
            annotation: Any = Annotated[bool, typer.Option(decls, **info)]
        elif typing.get_origin(base) is Literal:
            choices = enum.Enum(
                f"{settings_cls.__name__}_{f.name}", {str(c): str(c) for c in typing.get_args(base)}, type=str
            )  # type: ignore[misc]
            annotation = Annotated[choices, typer.Option(flag, **info)]
            default = choices(default)
        elif typing.get_origin(base) is tuple:
            inner = typing.get_args(base)[0]
            annotation = Annotated[list[inner] | None, typer.Option(flag, **info)]  # type: ignore[valid-type]
            default = None
        else:
            annotation = Annotated[base | None if optional else base, typer.Option(flag, **info)]
        params.append(
            inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation)
        )
    return params


def settings_from_options(settings_cls: type, values: dict[str, Any]) -> Any:
    """A stage's settings from the values its options gave (repeatable options as tuples)."""
    given = {}
    for key, value in values.items():
        if isinstance(value, enum.Enum):
            value = value.value
        elif isinstance(value, list) or (value is None and _is_tuple(settings_cls, key)):
            value = tuple(value or ())
        given[key] = value
    return make_settings(settings_cls, given, "options")


def _is_tuple(settings_cls: type, name: str) -> bool:
    return typing.get_origin(field_types(settings_cls)[name]) is tuple


def command_with(
    parent: typer.Typer,
    name: str,
    doc: str,
    params: list[inspect.Parameter],
    body: Callable[..., None],
) -> None:
    """Register ``body(**values)`` as command ``name`` with the parameters ``params``."""

    def command(**values: Any) -> None:
        body(**values)

    command.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    command.__annotations__ = {p.name: p.annotation for p in params}
    command.__doc__ = doc
    command.__name__ = name.replace("-", "_")
    parent.command(name)(command)


def common_parameters(*, executor: bool = False) -> list[inspect.Parameter]:
    """``--workers``/``--scheduler`` (for stages that spread work) and ``--json``, ``-v``, ``-q``."""
    kw = inspect.Parameter.KEYWORD_ONLY
    out = []
    if executor:
        out += [
            inspect.Parameter("workers", kw, default=None, annotation=WorkersOpt),
            inspect.Parameter("scheduler", kw, default=None, annotation=SchedulerOpt),
        ]
    out += [
        inspect.Parameter("as_json", kw, default=False, annotation=JsonOpt),
        inspect.Parameter("verbose", kw, default=0, annotation=VerboseOpt),
        inspect.Parameter("quiet", kw, default=False, annotation=QuietOpt),
    ]
    return out


def dive_parameter() -> inspect.Parameter:
    return inspect.Parameter("dive", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=DiveArg)


def stage_command(parent: typer.Typer, stage: Stage, name: str, doc: str) -> None:
    """Register the command of a pipeline stage: ``auvnav NAME DIVE [settings] [--json -v -q]``.

    It runs the stage now (whatever its key says), then the report stage so that the figures drawn
    from the products are up to date, and prints the stage's summary.
    """
    from auvnav.pipeline import run_stage

    fields = [f.name for f in dataclasses.fields(stage.settings)]

    def body(**values: Any) -> None:
        setup_logging(values.pop("verbose"), values.pop("quiet"))
        as_json = values.pop("as_json")
        dive = values.pop("dive")
        allow_outside = values.pop("allow_outside")
        executor = {k: values.pop(k) for k in ("workers", "scheduler") if k in values}
        settings = settings_from_options(stage.settings, {k: values[k] for k in fields})
        with progress_bars(as_json or logging.getLogger().level > logging.INFO) as progress:
            summary = run_stage(
                dive, stage.name, settings, progress=progress, allow_outside=allow_outside, **executor
            )
        if stage.name != "report":
            run_stage(dive, "report")
        emit(summary, stage.describe(summary), as_json=as_json)

    params = [
        dive_parameter(),
        *setting_parameters(stage.settings),
        inspect.Parameter(
            "allow_outside", inspect.Parameter.KEYWORD_ONLY, default=False, annotation=AllowOutsideOpt
        ),
        *common_parameters(executor=stage.uses_executor),
    ]
    command_with(parent, name, doc, params, body)
