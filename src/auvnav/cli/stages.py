"""``auvnav process`` and the command of each pipeline stage (navigate, loops, slam, depth, coverage, recon,
report)."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Annotated, Any

import typer

from auvnav.cli.common import (
    AllowOutsideOpt,
    DiveArg,
    JsonOpt,
    QuietOpt,
    SchedulerOpt,
    VerboseOpt,
    WorkersOpt,
    app,
    emit,
    progress_bars,
    setup_logging,
    stage_command,
)
from auvnav.config import load_yaml, parse_yaml
from auvnav.errors import ConfigError

log = logging.getLogger("auvnav")


def _register() -> None:
    from auvnav.pipeline import BY_NAME

    stage_command(
        app, BY_NAME["nav"], "navigate", "Dead reckoning, filter and smoother; writes DIVE/products/nav/."
    )
    stage_command(
        app,
        BY_NAME["vision"],
        "loops",
        "Stereo features, loop-closure candidates from the navigation, verification; writes DIVE/products/vision/.",
    )
    stage_command(
        app,
        BY_NAME["slam"],
        "slam",
        "SLAM pose graph (GTSAM): DVL, attitude, depth, compass, fixes, loops; writes DIVE/products/slam/.",
    )
    stage_command(
        app,
        BY_NAME["depth"],
        "depth",
        "Check pressure depth against loop closures (paper Fig. 6); writes DIVE/products/depth/.",
    )
    from auvnav.cli.coverage import DEFAULT_COMMAND, coverage_app

    stage_command(
        coverage_app,
        BY_NAME["coverage"],
        DEFAULT_COMMAND,
        "The coverage stage (auvnav coverage DIVE): image footprints on a map grid, gaps, overlap, "
        "line spacing ('accordion', 'figure 8'); writes DIVE/products/coverage/.",
    )
    stage_command(
        app,
        BY_NAME["recon"],
        "recon",
        "Dense stereo, TSDF mesh, DEM and orthophoto (GeoTIFF), false relief on revisits (paper Fig. 11); "
        "writes DIVE/products/recon/.",
    )
    from auvnav.cli import report  # noqa: F401 (auvnav report DIVE|CAMPAIGN: the report stage or a campaign's page)


_register()


def _settings_file(path: Path) -> dict[str, dict[str, Any]]:
    """A settings file: a mapping of stage names to their settings; paths relative to the file."""
    data, problems = load_yaml(path, str(path))
    if problems:
        raise ConfigError(str(problems[0]))
    if data is None:
        return {}
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise ConfigError(f"{path}: expected a mapping of stage names to mappings of settings")
    return {str(k): v for k, v in data.items()}


def _assignments(items: list[str]) -> dict[str, dict[str, Any]]:
    """``--set stage.key=value`` options as stage -> key -> value (the value parsed as YAML)."""
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        name, eq, text = item.partition("=")
        stage, dot, key = name.partition(".")
        if not eq or not dot or not stage or not key:
            raise typer.BadParameter(f"{item!r}: expected STAGE.KEY=VALUE", param_hint="--set")
        value, problems = parse_yaml(text, f"--set {item}")
        if problems:
            raise ConfigError(str(problems[0]))
        out.setdefault(stage, {})[key] = text if isinstance(value, (dict, list)) else value
    return out


@app.command()
def process(
    dive: DiveArg,
    only: Annotated[
        list[str] | None,
        typer.Option("--only", metavar="STAGE", help="Run only this stage (repeat for more)."),
    ] = None,
    start: Annotated[
        str | None, typer.Option("--from", metavar="STAGE", help="Run from this stage on.")
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Run the selected stages even when up to date.")
    ] = False,
    dry_run: Annotated[
        bool, typer.Option("--dry-run", help="Say what would run and why; run nothing.")
    ] = False,
    settings_file: Annotated[
        Path | None,
        typer.Option(
            "--settings",
            metavar="FILE",
            help="YAML: stage names to their settings (e.g. slam: {robust: huber}).",
        ),
    ] = None,
    assignments: Annotated[
        list[str] | None,
        typer.Option("--set", metavar="STAGE.KEY=VALUE", help="One setting of one stage (repeat for more)."),
    ] = None,
    compass_correction: Annotated[
        Path | None,
        typer.Option(
            "--compass-correction", help="Correction file for every stage that takes one (nav, slam)."
        ),
    ] = None,
    loops: Annotated[
        Path | None,
        typer.Option(
            "--loops", help="Loop closures for every stage that reads them (slam, depth); no loop stage."
        ),
    ] = None,
    tide: Annotated[
        Path | None,
        typer.Option("--tide", help="Tide constituent file for every stage that takes one (slam, depth)."),
    ] = None,
    allow_outside: AllowOutsideOpt = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Every stage the dive's data allows, in order; a rerun does only what changed (resumable)."""
    from auvnav.pipeline import STAGES, stage_named
    from auvnav.pipeline import process as run
    from auvnav.stagekit import make_settings

    setup_logging(verbose, quiet)
    values: dict[str, dict[str, Any]] = {}
    if settings_file is not None:  # file settings are relative to the settings file's folder
        for name, given in _settings_file(settings_file).items():
            try:
                stage = stage_named(name)
            except ConfigError as err:
                raise ConfigError(f"{settings_file}: {err}") from None
            values[stage.name] = dataclasses.asdict(
                make_settings(stage.settings, given, f"{settings_file}: {name}", base=settings_file.parent)
            )
    for name, given in _assignments(assignments or []).items():
        values.setdefault(stage_named(name).name, {}).update(given)
    shortcuts = {"compass_correction": compass_correction, "loops": loops, "tide": tide}
    for stage in STAGES:
        names = {f.name for f in dataclasses.fields(stage.settings)}
        for key, value in shortcuts.items():
            if value is not None and key in names:
                values.setdefault(stage.name, {})[key] = value
    settings = {
        name: make_settings(stage_named(name).settings, given, f"{name} settings")
        for name, given in values.items()
    }
    skip = {} if loops is None else {"vision": f"loop closures given: {loops}"}
    say = (lambda line: typer.echo(line, err=True)) if not (as_json or quiet) else None
    with progress_bars(as_json or quiet) as progress:
        result = run(
            dive,
            settings=settings,
            only=only,
            start=start,
            force=force,
            dry_run=dry_run,
            skip=skip,
            scheduler=scheduler,
            workers=workers,
            say=say,
            progress=progress,
            allow_outside=allow_outside,
        )
    lines = [f"{dive}: " + ", ".join(f"{o.stage} {o.status}" for o in result.outcomes)]
    for o in result.failed:
        lines.append(f"{o.stage} failed: {o.reason.splitlines()[0]}")
    emit(result.summary(), "\n".join(lines), as_json=as_json)
    if result.failed:
        first = result.failed[0]
        raise ConfigError(f"{dive}: stage {first.stage} failed: {first.reason.splitlines()[0]}") from None
