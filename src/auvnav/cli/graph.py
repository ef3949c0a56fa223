"""``auvnav graph``: any 2D or 3D pose-graph file (g2o, TORO) optimised."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from auvnav.cli.common import JsonOpt, OverwriteOpt, QuietOpt, VerboseOpt, app, emit, setup_logging

graph_app = typer.Typer(
    help="Pose-graph files (g2o, TORO): optimise any 2D or 3D graph.", no_args_is_help=True
)
app.add_typer(graph_app, name="graph")


class _RobustKernel(str, Enum):
    none = "none"
    huber = "huber"
    cauchy = "cauchy"


class _InitialGuess(str, Enum):
    file = "file"
    chordal = "chordal"


@graph_app.command("optimize")
def graph_optimize(
    graph_file: Annotated[
        Path, typer.Argument(metavar="IN", help="A g2o or TORO pose-graph file, 2D or 3D.")
    ],
    out: Annotated[Path, typer.Option("--out", help="The optimised graph, g2o.")],
    robust: Annotated[
        _RobustKernel, typer.Option("--robust", help="Kernel on loop closures; lists those it rejects.")
    ] = _RobustKernel.none,
    initial: Annotated[
        _InitialGuess,
        typer.Option("--initial", help="Initial guess: the file's vertices or a chordal relaxation."),
    ] = _InitialGuess.file,
    overwrite: OverwriteOpt = False,
    as_json: JsonOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Optimise a pose graph (Levenberg-Marquardt); print its chi-square cost before and after."""
    from auvnav.slam.g2o import read_g2o, write_g2o
    from auvnav.slam.solve import optimize_batch
    from auvnav.streams import ensure_writable

    setup_logging(verbose, quiet)
    ensure_writable(out, overwrite=overwrite)
    result = optimize_batch(read_g2o(graph_file), robust=robust.value, initial=initial.value)
    write_g2o(result.graph, out, overwrite=overwrite)
    summary = {**result.summary(), "output": str(out)}
    graph = result.graph
    lines = [
        f"{graph_file}: {graph.dim}D, {graph.n_poses} poses, {graph.n_edges} edges",
        f"  cost before  {result.cost_before:.10g}",
        f"  cost after   {result.cost_after:.10g}",
        f"  {result.iterations} iterations, {result.seconds:.2f} s",
    ]
    if result.robust != "none":
        n_loops = int((~graph.is_odometry).sum())
        lines.append(f"  {result.robust} kernel rejects {len(result.rejected)} of {n_loops} loop closures")
    lines.append(f"wrote {out}")
    emit(summary, "\n".join(lines), as_json=as_json)
