"""Strict YAML loading and the problem messages every configuration reader shares.

Every YAML file the project reads (dive.yaml, vehicle.yaml, missions, correction files, settings,
camera calibrations) goes through :func:`load_yaml` or :func:`parse_yaml`, which refuse what a
person editing the file would not mean: aliases (``&a``/``*a``, the "billion laughs" that expand a
few hundred bytes into gigabytes), the same key twice in one mapping (YAML itself says keys are
unique; PyYAML lets the last win silently), nesting deeper than :data:`MAX_DEPTH`, files that are
not regular files (a named pipe would block for ever) or larger than :data:`MAX_BYTES`, and tags
other than YAML's core ones (``!!timestamp``, ``!!binary``, ``!!set``, ``<<`` merge keys). Plain
scalars are resolved by the YAML 1.2 core schema, not PyYAML's YAML 1.1: only ``true``/``false``
are booleans (``yes``, ``no``, ``on``, ``off`` stay text, so ``heading_reference: on`` cannot turn
into True), ``1e-3`` is a number, ``012`` is twelve and ``1:30`` is text; dates stay text for the
schema to parse. A syntax error names its line. Values quoted in messages are cut to
:data:`MAX_QUOTE` characters (:func:`quote`).

Paths a dive names are confined to its folder: :func:`outside` says where a path that leaves it (by
``..``, an absolute path or a symbolic link) really leads.
"""

from __future__ import annotations

import re
import reprlib
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
#: Longest integer literal read from YAML, digits (Python refuses to convert more than 4300).
MAX_INT_DIGITS = 400


def cut(text: str, limit: int = MAX_QUOTE) -> str:
    """``text`` cut to ``limit`` characters with an ellipsis and the full length."""
    if len(text) <= limit:
        return text
    return f"{text[: limit - 1]}… ({len(text)} characters)"


def quote(value: Any, limit: int = MAX_QUOTE) -> str:
    """``repr(value)``, cut to ``limit`` characters with an ellipsis and the full length.

    Long strings and containers are cut before they are formatted (:mod:`reprlib`), so quoting a
    200 MB value costs nothing.
    """
    if isinstance(value, int) and value.bit_length() > 4 * limit:
        return f"<an integer of {value.bit_length()} bits>"
    short = repr(value[: 2 * limit]) if isinstance(value, (str, bytes)) else _REPR.repr(value)
    if len(short) <= limit and not (isinstance(value, (str, bytes)) and len(value) > 2 * limit):
        return short
    if isinstance(value, (str, bytes)):
        size = f"{len(value)} characters"
    elif isinstance(value, (list, tuple, dict, set)):
        size = f"{len(value)} items"
    else:
        size = f"{len(short)} characters"
    return f"{short[: limit - 1]}… ({size})"


def _short_repr() -> reprlib.Repr:
    r = reprlib.Repr()
    r.maxstring = r.maxother = 2 * MAX_QUOTE
    r.maxlist = r.maxtuple = r.maxdict = r.maxset = MAX_QUOTE // 4
    r.maxlong = 2 * MAX_QUOTE
    r.maxlevel = 4
    return r


_REPR = _short_repr()


_CORE = "tag:yaml.org,2002:"
# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution), plain scalars only.
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_NULL = re.compile(r"^(?:~|null|Null|NULL|)$")
_INT = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT = re.compile(
    r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
)
_ACCEPTED_TAGS = {_CORE + t for t in ("str", "int", "float", "bool", "null", "seq", "map")}


def _resolvers() -> dict[Any, list[tuple[str, re.Pattern[str]]]]:
    """First character -> (tag, pattern) of every implicit resolver of the YAML 1.2 core schema."""
    table: dict[Any, list[tuple[str, re.Pattern[str]]]] = {}
    for tag, pattern, first in (
        (_CORE + "bool", _BOOL, "tTfF"),
        (_CORE + "int", _INT, "-+0123456789"),
        (_CORE + "float", _FLOAT, "-+0123456789."),
        (_CORE + "null", _NULL, ["~", "n", "N", ""]),
    ):
        for char in first:
            table.setdefault(char, []).append((tag, pattern))
    return table


#: libyaml's parser when PyYAML was built with it (scanning in C: 1 MB in milliseconds, not seconds).
_BASE_LOADER: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _check_events(text: str) -> None:
    """Refuse aliases and nesting deeper than :data:`MAX_DEPTH` from the parser's events, before
    anything is composed (so the loader itself may be libyaml's, whose composer is not Python)."""
    depth = 0
    for event in yaml.parse(text, Loader=_BASE_LOADER):
        if isinstance(event, yaml.AliasEvent):
            raise ComposerError(
                None, None, "aliases (*name) are not accepted: write the value out", event.start_mark
            )
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                raise ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels", event.start_mark)
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


class _StrictLoader(_BASE_LOADER):  # type: ignore[misc, valid-type]
    """A safe loader that refuses duplicate keys and non-core tags, and resolves plain scalars by
    the YAML 1.2 core schema (aliases and depth are refused first, by :func:`_check_events`)."""

    _mapping_tags: frozenset[str] = frozenset()
    yaml_implicit_resolvers = _resolvers()

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        if node.tag not in _ACCEPTED_TAGS:
            if node.tag in self._mapping_tags and isinstance(node, yaml.MappingNode):
                node.tag = _CORE + "map"
            else:
                tag = node.tag.replace(_CORE, "!!")
                raise ConstructorError(None, None, f"tag {quote(tag)} is not accepted", node.start_mark)
        return super().construct_object(node, deep=deep)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:
                raise ConstructorError(
                    None, None, "a key that is a list or mapping is not accepted", key_node.start_mark
                ) from None
            if duplicate:
                raise ConstructorError(
                    None, None, f"key {quote(key)} appears twice in one mapping", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)

    def flatten_mapping(self, node: yaml.MappingNode) -> None:
        """No merge keys (``<<``): YAML 1.2 has none; with the resolvers above ``<<`` is text."""

    def _scalar(self, node: yaml.Node, pattern: re.Pattern[str], what: str) -> str:
        """A scalar node's text, checked against the core schema's pattern for its tag."""
        value = self.construct_scalar(node)  # type: ignore[arg-type]
        if not isinstance(value, str) or not pattern.match(value):
            raise ConstructorError(None, None, f"{quote(value)} is not {what}", node.start_mark)
        return value

    def construct_core_bool(self, node: yaml.Node) -> bool:
        return self._scalar(node, _BOOL, "true or false").lower() == "true"

    def construct_core_int(self, node: yaml.Node) -> int:
        text = self._scalar(node, _INT, "an integer")
        if len(text) > MAX_INT_DIGITS:
            raise ConstructorError(None, None, f"integer of {len(text)} digits", node.start_mark)
        if text.startswith(("0o", "0x")):
            return int(text[2:], 8 if text[1] == "o" else 16)
        return int(text)

    def construct_core_float(self, node: yaml.Node) -> float:
        text = self._scalar(node, _FLOAT, "a number")
        if text.lower().endswith(("inf", "nan")):
            return float(text.replace(".", ""))
        return float(text)


_StrictLoader.add_constructor(_CORE + "bool", _StrictLoader.construct_core_bool)
_StrictLoader.add_constructor(_CORE + "int", _StrictLoader.construct_core_int)
_StrictLoader.add_constructor(_CORE + "float", _StrictLoader.construct_core_float)


def parse_yaml(text: str, display: str, *, mapping_tags: tuple[str, ...] = ()) -> tuple[Any, list[Problem]]:
    """Parse YAML text strictly (see the module docstring); a problem names the line.

    ``mapping_tags`` are tags accepted on mappings, read as plain mappings (``"opencv-matrix"`` for
    the ``!!opencv-matrix`` of OpenCV's FileStorage).
    """
    loader: type[_StrictLoader] = _StrictLoader
    if mapping_tags:
        tags = frozenset(_CORE + t for t in mapping_tags)
        loader = type("_TaggedLoader", (_StrictLoader,), {"_mapping_tags": tags})
    try:
        _check_events(text)
        return yaml.load(text, Loader=loader), []
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or type(err).__name__
        if "maximum nesting depth" in problem:  # libyaml's own limit, met before ours in flow style
            problem = f"nested deeper than {MAX_DEPTH} levels"
        return None, [Problem(display, f"not valid YAML{where}: {problem}")]
    except RecursionError:
        return None, [Problem(display, f"not valid YAML: nested deeper than {MAX_DEPTH} levels")]
    except (ValueError, TypeError, OverflowError) as err:  # a constructor's own complaint
        return None, [Problem(display, f"not valid YAML: {quote(str(err))}")]


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
        key = cut(".".join(str(p) for p in e["loc"])) or "(top level)"
        msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"].removeprefix("Value error, ")
        if e["type"] == "missing":
            msg = "missing"
        if e["type"] not in ("extra_forbidden", "missing", "value_error") and "input" in e:
            msg += f" (found {quote(e['input'])})"
        out.append(Problem(display, f"key {key}: {msg}"))
    return out


def _either_schema() -> dict[Any, list[tuple[str, re.Pattern[str]]]]:
    """PyYAML's YAML 1.1 resolvers and the strict loader's YAML 1.2 ones together: a string that
    either would read as something else is written quoted."""
    table = {k: list(v) for k, v in yaml.SafeDumper.yaml_implicit_resolvers.items()}
    for k, v in _StrictLoader.yaml_implicit_resolvers.items():
        table.setdefault(k, []).extend(v)
    return table


class NoAliasDumper(yaml.SafeDumper):
    """A safe dumper that writes a value out each time it appears (never ``&id``/``*id``) and
    quotes every string that YAML 1.1 or 1.2 would read as something else (``yes``, ``1e5``), so
    every file the project writes is one its own strict loader, or any other, reads back as written."""

    yaml_implicit_resolvers = _either_schema()

    def ignore_aliases(self, data: Any) -> bool:
        return True


def dump_yaml(data: Any, **options: Any) -> str:
    """YAML text of plain data, keys in insertion order unless ``sort_keys``; no aliases."""
    options.setdefault("sort_keys", False)
    return yaml.dump(data, Dumper=NoAliasDumper, **options)


def outside(root: Path, path: Path) -> Path | None:
    """Where ``path`` really leads when that is outside the folder ``root`` (``..``, an absolute
    path, or a symbolic link on the way), else None. Both are resolved as the file system has them
    now; a path that does not exist is judged by what exists of it."""
    real_root = Path(root).resolve()
    real = Path(root, path).resolve()
    return None if real == real_root or real.is_relative_to(real_root) else real
