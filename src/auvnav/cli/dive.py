"""``auvnav validate`` and ``auvnav evaluate``: a dive folder checked, a simulated dive's products scored."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from auvnav.cli.common import (
    AllowOutsideOpt,
    DiveArg,
    JsonOpt,
    QuietOpt,
    VerboseOpt,
    app,
    emit,
    log,
    setup_logging,
)
from auvnav.errors import DiveFormatError


@app.command()
def validate(
    dive: DiveArg,
    allow_outside: AllowOutsideOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Check a dive folder: every problem with its file, row and column; a summary when it is valid.

    Every check the stages make of the dive's files is made here, so a dive that validates is one
    they read. Files the dive names outside its folder are errors unless --allow-outside.
    """
    from auvnav.dive import validate_dive

    setup_logging(verbose, quiet)
    report = validate_dive(dive, allow_outside=allow_outside)
    for w in report.warnings:
        log.warning(w)
    if not report.ok:
        raise DiveFormatError(report.problems)
    valid_dive = report.dive
    if valid_dive is None:  # cannot happen: a report without problems carries its dive
        raise RuntimeError("validate_dive returned no dive and no problems")
    t0, t1 = valid_dive.time_span_s()
    summary = {
        "dive": str(dive),
        "valid": True,
        "duration_s": t1 - t0,
        "streams": {
            s.name: {
                "file": s.file,
                "rows": s.rows,
                "rate_hz": s.rate_hz,
                "gaps": [{"start_s": a, "length_s": b} for a, b in s.gaps],
            }
            for s in report.streams
        },
        "warnings": report.warnings,
    }
    lines = [f"{dive}: valid dive '{valid_dive.info.name}', {(t1 - t0) / 3600:.2f} h"]
    for s in report.streams:
        gaps = f", {len(s.gaps)} gap(s), longest {max(g[1] for g in s.gaps):.1f} s" if s.gaps else ""
        lines.append(f"  {s.name:<13} {s.file:<24} {s.rows:>8} rows  {s.rate_hz:7.2f} Hz{gaps}")
    emit(summary, "\n".join(lines), as_json=as_json)


@app.command()
def evaluate(
    dive: DiveArg,
    compass_correction: Annotated[
        Path | None,
        typer.Option("--compass-correction", help="Score this correction file against the true deviation."),
    ] = None,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Score a simulated dive's products against its truth (the products that exist)."""
    from auvnav.evaluate import evaluate_dive, format_scores

    setup_logging(verbose, quiet)
    result = evaluate_dive(dive, compass_correction=compass_correction)
    emit(result, format_scores(result), as_json=as_json)
