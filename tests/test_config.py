"""The strict YAML loader: YAML 1.2 core-schema scalars, and files the project writes read back as written."""

from __future__ import annotations

import math

import pytest

from auvnav.config import dump_yaml, parse_yaml, quote

# Plain scalars as the YAML 1.2 core schema reads them (https://yaml.org/spec/1.2.2/#1032-tag-resolution);
# PyYAML's YAML 1.1 reads the first six as True, False, True, 1e-3 as text, 012 as 10 and 1:30 as 90.
CORE_SCHEMA = [
    ("yes", "yes"),
    ("no", "no"),
    ("on", "on"),
    ("off", "off"),
    ("y", "y"),
    ("n", "n"),
    ("1e-3", 0.001),
    ("012", 12),
    ("1:30", "1:30"),
    ("1_000", "1_000"),
    ("true", True),
    ("False", False),
    ("0x1f", 31),
    ("0o17", 15),
    ("~", None),
    ("2009-10-15", "2009-10-15"),
]


@pytest.mark.parametrize(("text", "value"), CORE_SCHEMA)
def test_plain_scalars_follow_the_yaml_1_2_core_schema(text: str, value: object) -> None:
    data, problems = parse_yaml(f"a: {text}\n", "x.yaml")
    assert problems == []
    assert data["a"] == value and type(data["a"]) is type(value)


def test_what_the_project_writes_it_reads_back_as_written() -> None:
    data = {"a": "1e5", "b": "yes", "c": "012", "d": "on", "e": 1e300, "f": True, "g": None, "h": [1, "0x10"]}
    back, problems = parse_yaml(dump_yaml(data), "x.yaml")
    assert problems == [] and back == data
    nan, _ = parse_yaml(dump_yaml({"x": float("nan")}), "x.yaml")
    assert math.isnan(nan["x"])


def test_quote_cuts_long_values_without_formatting_them_whole() -> None:
    text = quote("x" * 10**7)
    assert len(text) < 120 and text.endswith("(10000000 characters)")
    assert len(quote(list(range(10**6)))) < 120
    assert quote(10**5000) == "<an integer of 16610 bits>"
