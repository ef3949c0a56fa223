"""``auvnav process``: every stage a dive's data allows, in order, resumable (DESIGN sections 2 and 9).

The stages (:data:`STAGES`) run in dependency order. Each has a key: the SHA-256 of its settings
(a file named by a setting counts by its content), the content of every file its result depends on
(:attr:`~auvnav.stagekit.Stage.inputs`: the dive's own files and the products of the stages before
it) and the package version. The key is recorded in ``products/<stage>/stage.json``, written last
(:class:`~auvnav.products.ProductSet`). A stage whose recorded key matches is up to date and is not
run again; one whose inputs or settings changed runs, and the stages after it run when what it wrote
changed what they read. ``force`` runs the selected stages whatever their keys say.

A stage the dive's data does not allow (no images, no loop closures, headings that cannot give a
correction) is skipped with the reason. A stage that fails with a known error (bad input) is
reported, the stages that read its products are skipped, and the others still run.

Files are hashed once: ``products/cache/hashes.json`` remembers each file's size, modification time
and digest, so an unchanged rerun only stats the files (images included). One ``auvnav`` at a time
works on a dive (``products/.lock``); at the start of a run, what a killed run left (temporary
folders and files) is removed and an interrupted swap of a stage's products is completed
(:func:`auvnav.products.recover`). A run on a dive without ``products/`` that fails before any stage
writes takes the lock and the hashes away again: bad input leaves no folder behind.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import json
import logging
import os
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from auvnav import __version__
from auvnav import products as P
from auvnav.compass.stage import STAGE as COMPASS
from auvnav.coverage.stage import STAGE as COVERAGE
from auvnav.depth.stage import STAGE as DEPTH
from auvnav.dive import outside_inputs
from auvnav.errors import AuvnavError, ConfigError, InsufficientDataError
from auvnav.executor import Executor, make_executor
from auvnav.nav.stage import STAGE as NAV
from auvnav.recon.stage import STAGE as RECON
from auvnav.report.stage import STAGE as REPORT
from auvnav.slam.stage import STAGE as SLAM
from auvnav.stagekit import Progress, Stage, StageContext, StageSkipped, settings_mapping
from auvnav.streams import atomic_write
from auvnav.vision.stage import STAGE as VISION

log = logging.getLogger(__name__)

#: Every stage, in the order they run.
STAGES: tuple[Stage, ...] = (NAV, VISION, SLAM, COMPASS, DEPTH, COVERAGE, RECON, REPORT)
BY_NAME: dict[str, Stage] = {s.name: s for s in STAGES}
#: Other names a user may give a stage (its command's name).
ALIASES = {"navigate": "nav", "loops": "vision"}
HASHES_FILE = "hashes.json"
LOCK_FILE = ".lock"


def stage_named(name: str) -> Stage:
    """The stage called ``name`` (or by its command's name); ConfigError naming the choices."""
    key = ALIASES.get(name, name)
    if key not in BY_NAME:
        raise ConfigError(f"no stage {name!r} (stages: {', '.join(BY_NAME)})")
    return BY_NAME[key]


# ---------------------------------------------------------------------------------------------
# Keys
# ---------------------------------------------------------------------------------------------


class FileHashes:
    """SHA-256 digests of files, remembered by size and modification time (``hashes.json``)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self._known: dict[str, list[Any]] = {}
        self._changed = False
        if path is not None and path.is_file():
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
                self._known = data if isinstance(data, dict) else {}
            except (OSError, ValueError):
                self._known = {}

    def digest(self, path: Path) -> str:
        """The file's digest (``missing`` when it does not exist)."""
        try:
            st = os.stat(path)
        except OSError:
            return "missing"
        name = str(Path(path).resolve())
        known = self._known.get(name)
        if known is not None and known[:2] == [st.st_size, st.st_mtime_ns]:
            return str(known[2])
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        self._known[name] = [st.st_size, st.st_mtime_ns, h.hexdigest()]
        self._changed = True
        return h.hexdigest()

    def save(self) -> None:
        if self.path is None or not self._changed:
            return
        text = json.dumps(self._known, separators=(",", ":"))
        atomic_write(self.path, lambda p: p.write_text(text, encoding="utf-8"))
        self._changed = False


def _fingerprint(settings: Any) -> dict[str, Any]:
    """Settings as keyed: a file a setting names counts by its content (in the inputs), not its name."""
    out = {}
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if isinstance(value, Path):
            value = "<file>"
        elif isinstance(value, tuple):
            value = ["<file>" if isinstance(v, Path) else v for v in value]
        out[f.name] = value
    return out


def stage_key(
    stage: Stage, dive: Path, settings: Any, hashes: FileHashes, *, allow_outside: bool = False
) -> tuple[str, dict[str, Any]]:
    """The stage's key and what it is made of (``settings``, ``inputs``, ``version``).

    The dive's files that lead outside its folder are hashed only with ``allow_outside``.
    """
    files = stage.inputs(dive, settings)
    if allow_outside:
        files = outside_inputs(dive, files)
    inputs = {label: hashes.digest(path) for label, path in sorted(files.items())}
    material = {
        "stage": stage.name,
        "version": __version__,
        "settings": _fingerprint(settings),
        "inputs": inputs,
    }
    key = hashlib.sha256(json.dumps(material, sort_keys=True).encode()).hexdigest()
    return key, material


def _why_stale(record: dict[str, Any] | None, key: str, material: dict[str, Any]) -> str:
    """Why a stage must run: no products, or what changed since they were made ("" when up to date)."""
    if record is None:
        return "no products yet"
    if record.get("key") == key:
        return ""
    if record.get("version") != material["version"]:
        return f"made by auvnav {record.get('version')}"
    if record.get("settings") != material["settings"]:
        return "settings changed"
    old = record.get("inputs") or {}
    changed = sorted(k for k in set(old) | set(material["inputs"]) if old.get(k) != material["inputs"].get(k))
    if changed:
        more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
        return f"inputs changed: {', '.join(changed[:3])}{more}"
    return "key changed"


# ---------------------------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------------------------


@dataclass
class Outcome:
    """What became of one stage in a run."""

    stage: str
    status: str  # "ran", "up to date", "skipped", "failed", "would run", "not selected"
    reason: str = ""
    seconds: float = 0.0
    summary: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class RunResult:
    """Every stage's outcome, in order."""

    dive: str
    outcomes: list[Outcome] = field(default_factory=list)

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    def summary(self) -> dict[str, Any]:
        return {"dive": self.dive, "stages": [o.as_dict() for o in self.outcomes]}


@contextlib.contextmanager
def dive_lock(dive: Path) -> Iterator[None]:
    """Hold ``products/.lock`` for the block: one ``auvnav`` at a time works on a dive."""
    root = Path(dive) / P.PRODUCTS
    try:
        root.mkdir(parents=True, exist_ok=True)
        fh = open(root / LOCK_FILE, "a+")
    except PermissionError as err:
        raise AuvnavError(f"{root}: not writable ({err.strerror})") from err
    except (NotADirectoryError, FileExistsError) as err:
        raise AuvnavError(f"{root}: exists and is not a folder") from err
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            if err.errno in (errno.EAGAIN, errno.EACCES):
                raise AuvnavError(
                    f"{dive}: another auvnav is processing this dive; wait for it to finish"
                ) from None
            raise
        yield
    finally:
        fh.close()


def _sweep(dive: Path) -> None:
    """Remove what killed runs left: unfinished stage folders and temporary files in the caches."""
    for stage in STAGES:
        P.recover(dive, stage.name)
    cache = Path(dive) / P.PRODUCTS / P.CACHE
    if cache.is_dir():
        for tmp in cache.rglob(".*.tmp"):
            tmp.unlink(missing_ok=True)


def _select(only: Sequence[str] | None, start: str | None) -> set[str]:
    names = [s.name for s in STAGES]
    if only and start:
        raise ConfigError("give --only or --from, not both")
    if only:
        return {stage_named(n).name for n in only}
    if start:
        return set(names[names.index(stage_named(start).name) :])
    return set(names)


def default_settings(overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Every stage's settings: the defaults, replaced by ``overrides`` (stage name to settings)."""
    out = {s.name: s.settings() for s in STAGES}
    for name, value in (overrides or {}).items():
        out[stage_named(name).name] = value
    return out


def process(
    dive: Path,
    *,
    settings: Mapping[str, Any] | None = None,
    only: Sequence[str] | None = None,
    start: str | None = None,
    force: bool = False,
    dry_run: bool = False,
    skip: Mapping[str, str] | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    say: Callable[[str], None] | None = None,
    progress: Progress | None = None,
    allow_outside: bool = False,
) -> RunResult:
    """Run every stage the dive's data allows (module docstring).

    Parameters
    ----------
    dive : Path
        A dive folder.
    settings : mapping, optional
        Stage name to its settings object; the others take their defaults.
    only : sequence of str, optional
        Run only these stages (those after them are not run).
    start : str, optional
        Run from this stage on (those before it are not run).
    force : bool
        Run the selected stages even when up to date.
    dry_run : bool
        Say what would run and why; run nothing, write nothing.
    skip : mapping, optional
        Stages not to run, with the reason to give (``vision``: "loop closures given").
    scheduler, workers : optional
        The executor of the per-item work (:func:`auvnav.executor.make_executor`).
    say : callable(str), optional
        Called with a line as each stage starts and ends.
    progress : callable(what, done, total), optional
        Per-item progress inside a stage.
    allow_outside : bool
        Read the files the dive names outside its folder (each is said); otherwise they are errors.
    """
    dive = Path(dive)
    if not dive.is_dir():
        raise AuvnavError(f"{dive}: not a dive folder (no such directory)")
    say = say or (lambda line: log.info(line))
    chosen = default_settings(settings)
    selected = _select(only, start)
    skip = dict(skip or {})
    result = RunResult(str(dive))
    if dry_run:
        _plan(dive, chosen, selected, force, skip, result, say, allow_outside)
        return result
    with _session(dive, scheduler, workers, progress, allow_outside) as (ctx, hashes):
        blocked: dict[str, str] = {}
        for stage in STAGES:
            outcome = _one(stage, ctx, chosen[stage.name], selected, force, skip, blocked, hashes, say)
            result.outcomes.append(outcome)
            if outcome.status in ("failed", "skipped"):
                blocked[stage.name] = outcome.status
            hashes.save()
    return result


def _one(
    stage: Stage,
    ctx: StageContext,
    settings: Any,
    selected: set[str],
    force: bool,
    skip: dict[str, str],
    blocked: dict[str, str],
    hashes: FileHashes,
    say: Callable[[str], None],
) -> Outcome:
    dive = ctx.dive
    if stage.name not in selected:
        return Outcome(stage.name, "not selected")
    failed_before = [n for n in stage.after if blocked.get(n) == "failed"]
    if failed_before:
        reason = f"{', '.join(failed_before)} failed"
        say(f"{stage.name}: skipped ({reason})")
        return Outcome(stage.name, "skipped", reason)
    reason = skip.get(stage.name) or stage.unavailable(dive, settings)
    if reason:
        say(f"{stage.name}: skipped ({reason})")
        return Outcome(stage.name, "skipped", reason)
    key, material = stage_key(stage, dive, settings, hashes, allow_outside=ctx.allow_outside)
    record = P.read_record(dive, stage.name)
    stale = "forced" if force else _why_stale(record, key, material)
    if not stale and record is not None:
        status = "skipped" if record.get("status") == "skipped" else "up to date"
        why = record.get("reason", "") if status == "skipped" else ""
        say(f"{stage.name}: {status}" + (f" ({why})" if why else ""))
        return Outcome(stage.name, status, why, 0.0, record.get("summary"))
    say(f"{stage.name}: running ({stale}): {stage.title}")
    started = time.perf_counter()
    try:
        summary, status, why = _execute(stage, ctx, settings, key, material)
    except AuvnavError as err:
        message = str(err).splitlines()[0] if str(err) else type(err).__name__
        say(f"{stage.name}: failed: {message}")
        return Outcome(stage.name, "failed", str(err), time.perf_counter() - started)
    seconds = time.perf_counter() - started
    say(
        f"{stage.name}: {'done' if status == 'ran' else 'skipped'} in {seconds:.1f} s"
        + (f" ({why})" if why else "")
    )
    return Outcome(stage.name, status, why, seconds, summary)


def _execute(
    stage: Stage, ctx: StageContext, settings: Any, key: str, material: dict[str, Any]
) -> tuple[dict[str, Any] | None, str, str]:
    """Run one stage into a new product set and swap it in; (summary, status, reason).

    A stage that finds the data cannot give its products (:class:`~auvnav.stagekit.StageSkipped`)
    is recorded like a run, with no products, so that an unchanged rerun does not try again.
    """
    record: dict[str, Any] = {
        "stage": stage.name,
        "key": key,
        "version": material["version"],
        "settings": material["settings"],
        "settings_given": settings_mapping(settings),
        "inputs": material["inputs"],
    }
    product_set = P.ProductSet(ctx.dive, stage.name)
    with product_set as out:
        started = time.perf_counter()
        try:
            summary: dict[str, Any] | None = stage.run(ctx, settings, out)
            status, why = "ran", ""
        except StageSkipped as err:
            for leftover in out.iterdir():  # what the stage wrote before it found out
                leftover.unlink() if leftover.is_file() else shutil.rmtree(leftover)
            summary, status, why = None, "skipped", str(err)
        record.update(status=status, reason=why, seconds=time.perf_counter() - started, summary=summary)
        product_set.commit(record)
    return summary, status, why


@contextlib.contextmanager
def _session(
    dive: Path,
    scheduler: str | None,
    workers: int | None,
    progress: Progress | None,
    allow_outside: bool = False,
) -> Iterator[tuple[StageContext, FileHashes]]:
    """The dive locked and swept, its file hashes, and an executor made on first use (closed after)."""
    executor: Executor | None = None

    def get_executor() -> Executor:
        nonlocal executor
        if executor is None:
            executor = make_executor(scheduler, workers)
        return executor

    root = Path(dive) / P.PRODUCTS
    fresh = not root.exists()
    with dive_lock(dive):
        _sweep(dive)
        hashes = FileHashes(P.cache_dir(dive, "") / HASHES_FILE)
        try:
            yield StageContext(dive, get_executor, progress, allow_outside), hashes
        finally:
            if executor is not None:
                executor.close()
            if fresh and root.is_dir() and _bookkeeping_only(root):
                shutil.rmtree(root, ignore_errors=True)  # failed before writing: leave no products folder
            else:
                hashes.save()


def _bookkeeping_only(root: Path) -> bool:
    """Whether the products folder holds nothing but the run's lock and file hashes."""
    cache = root / P.CACHE
    inside = {p.name for p in root.iterdir()}
    return inside <= {LOCK_FILE, P.CACHE} and (
        not cache.is_dir() or {p.name for p in cache.iterdir()} <= {HASHES_FILE}
    )


def run_stage(
    dive: Path,
    name: str,
    settings: Any | None = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Progress | None = None,
    allow_outside: bool = False,
) -> dict[str, Any]:
    """Run one stage now, whatever its key says (the stage's own command); its summary.

    ``allow_outside`` lets the stage read files the dive names outside its folder (each is said).

    Raises
    ------
    InsufficientDataError
        The dive's data does not allow the stage (the reason), or the stage found it could not run.
    AuvnavError
        Bad input, with the file and the problem.
    """
    stage = stage_named(name)
    dive = Path(dive)
    if not dive.is_dir():
        raise AuvnavError(f"{dive}: not a dive folder (no such directory)")
    settings = stage.settings() if settings is None else settings
    reason = stage.unavailable(dive, settings)
    if reason:
        raise InsufficientDataError(f"{dive}: {stage.name}: {reason}")
    with _session(dive, scheduler, workers, progress, allow_outside) as (ctx, hashes):
        key, material = stage_key(stage, dive, settings, hashes, allow_outside=allow_outside)
        summary, status, why = _execute(stage, ctx, settings, key, material)
    if status == "skipped":
        raise InsufficientDataError(f"{dive}: {stage.name}: {why}")
    return summary or {}


def _plan(
    dive: Path,
    chosen: dict[str, Any],
    selected: set[str],
    force: bool,
    skip: dict[str, str],
    result: RunResult,
    say: Callable[[str], None],
    allow_outside: bool = False,
) -> None:
    """``--dry-run``: what each stage would do, with no file written.

    A stage after one that would run is judged on the products as they are now: it will run if
    what the earlier stage writes changes what it reads.
    """
    hashes = FileHashes(P.cache_dir(dive, "") / HASHES_FILE)
    for stage in STAGES:
        settings = chosen[stage.name]
        if stage.name not in selected:
            result.outcomes.append(Outcome(stage.name, "not selected"))
            continue
        reason = skip.get(stage.name) or stage.unavailable(dive, settings)
        if reason:
            outcome = Outcome(stage.name, "skipped", reason)
        else:
            key, material = stage_key(stage, dive, settings, hashes, allow_outside=allow_outside)
            stale = "forced" if force else _why_stale(P.read_record(dive, stage.name), key, material)
            outcome = Outcome(stage.name, "would run" if stale else "up to date", stale)
        say(f"{stage.name}: {outcome.status}" + (f" ({outcome.reason})" if outcome.reason else ""))
        result.outcomes.append(outcome)
