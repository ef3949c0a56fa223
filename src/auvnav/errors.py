"""The exceptions auvnav raises for problems a user can fix.

Every known error derives from :class:`AuvnavError`; the command line turns them into one line on
stderr and exit code 1 (``auvnav.cli.main``). Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

from dataclasses import dataclass


class AuvnavError(Exception):
    """Base of every error a user can act on (bad input, missing file, bad option)."""


class ConfigError(AuvnavError):
    """A configuration file (dive.yaml, vehicle.yaml, mission, correction) is invalid."""


class OutputExistsError(AuvnavError):
    """An output exists and ``--overwrite`` was not given."""


class InsufficientDataError(AuvnavError):
    """The data cannot determine what was asked of it (too few samples, no overlap)."""


@dataclass(frozen=True)
class Problem:
    """One problem found in an input file.

    Parameters
    ----------
    file : str
        The file, relative to the dive folder where there is one.
    message : str
        What is wrong, in a phrase.
    row : int or None
        1-based data row (the header is row 0), where the problem has one.
    column : str or None
        The column or key, where the problem has one.
    """

    file: str
    message: str
    row: int | None = None
    column: str | None = None

    def __str__(self) -> str:
        where = self.file
        if self.row is not None:
            where += f": row {self.row}"
        if self.column is not None:
            where += f": column {self.column}"
        return f"{where}: {self.message}"


#: At most this many problems are printed, one line each; the rest are counted on one more line.
MAX_PROBLEM_LINES = 12


class DiveFormatError(AuvnavError):
    """A dive folder breaks the format; carries every problem found (:attr:`problems`), and says the
    first :data:`MAX_PROBLEM_LINES` of them, one line each, with a count of the rest."""

    def __init__(self, problems: list[Problem]) -> None:
        if not problems:
            raise ValueError("DiveFormatError needs at least one problem")
        self.problems = list(problems)
        lines = [str(p) for p in self.problems[:MAX_PROBLEM_LINES]]
        if len(self.problems) > MAX_PROBLEM_LINES:
            lines.append(f"... and {len(self.problems) - MAX_PROBLEM_LINES} more problems")
        super().__init__("\n".join(lines))
