"""Strict YAML loading and the problem messages every configuration reader shares.

Every YAML file the project reads (dive.yaml, vehicle.yaml, missions, correction files, settings,
camera calibrations) goes through :func:`load_yaml` or :func:`parse_yaml`, which refuse what a
person editing the file would not mean: aliases (``&a``/``*a``, the "billion laughs" that expand a
few hundred bytes into gigabytes), the same key twice in one mapping (YAML itself says keys are
unique; PyYAML lets the last win silently), nesting deeper than :data:`MAX_DEPTH`, files that are
not regular files (a named pipe would block for ever) or larger than :data:`MAX_BYTES`. A syntax
error names its line. Values quoted in messages are cut to :data:`MAX_QUOTE` characters
(:func:`quote`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError

from auvnav.errors import Problem

#: Largest YAML file read, bytes: a dive's configuration is kilobytes; a mission of 10,000 segments
#: a megabyte.
MAX_BYTES = 16 * 2**20
#: Deepest nesting of mappings and lists accepted (the project's own files nest four levels).
MAX_DEPTH = 32
#: Longest piece of a value quoted in a message, characters.
MAX_QUOTE = 80


def quote(value: Any, limit: int = MAX_QUOTE) -> str:
    """``repr(value)``, cut to ``limit`` characters with an ellipsis and the full length."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[: limit - 1]}… ({len(text)} characters)"


class _StrictLoader(yaml.SafeLoader):
    """A safe loader that refuses aliases, duplicate keys and deep nesting."""

    _depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise ComposerError(
                None, None, "aliases (*name) are not accepted: write the value out", event.start_mark
            )
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise ComposerError(
                    None, None, f"nested deeper than {MAX_DEPTH} levels", self.peek_event().start_mark
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:  # an unhashable key: let the base class say so
                break
            if duplicate:
                raise ConstructorError(
                    None, None, f"key {quote(key)} appears twice in one mapping", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def parse_yaml(text: str, display: str) -> tuple[Any, list[Problem]]:
    """Parse YAML text strictly (see the module docstring); a problem names the line."""
    try:
        return yaml.load(text, Loader=_StrictLoader), []
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or type(err).__name__
        return None, [Problem(display, f"not valid YAML{where}: {problem}")]
    except RecursionError:
        return None, [Problem(display, f"not valid YAML: nested deeper than {MAX_DEPTH} levels")]


def read_text(path: Path, display: str, *, max_bytes: int = MAX_BYTES) -> tuple[str | None, list[Problem]]:
    """A regular UTF-8 text file's content, or the problems that stop it being read."""
    try:
        if not path.exists():
            return None, [Problem(display, "file not found")]
        if not path.is_file():
            return None, [Problem(display, "not a regular file")]
        size = path.stat().st_size
        if size > max_bytes:
            return None, [Problem(display, f"too large ({size} bytes; at most {max_bytes})")]
        return path.read_bytes().decode("utf-8"), []
    except UnicodeDecodeError as err:
        return None, [Problem(display, f"not a text file (not UTF-8 at byte {err.start})")]
    except OSError as err:
        return None, [Problem(display, f"cannot be read ({err.strerror or type(err).__name__})")]


def load_yaml(path: Path, display: str) -> tuple[Any, list[Problem]]:
    """Read and parse a YAML file strictly; never raises for the file's content."""
    text, problems = read_text(Path(path), display)
    if text is None:
        return None, problems
    return parse_yaml(text, display)


def pydantic_problems(err: ValidationError, display: str) -> list[Problem]:
    """One problem per pydantic error, naming the key path (values quoted short)."""
    out = []
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"]
        if e["type"] not in ("extra_forbidden", "missing") and "input" in e:
            msg += f" (found {quote(e['input'])})"
        out.append(Problem(display, f"key {key}: {msg}"))
    return out


class NoAliasDumper(yaml.SafeDumper):
    """A safe dumper that writes a value out each time it appears (never ``&id``/``*id``), so every
    file the project writes is one its own strict loader reads."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def dump_yaml(data: Any, **options: Any) -> str:
    """YAML text of plain data, keys in insertion order unless ``sort_keys``; no aliases."""
    options.setdefault("sort_keys", False)
    return yaml.dump(data, Dumper=NoAliasDumper, **options)
