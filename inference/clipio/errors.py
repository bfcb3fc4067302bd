"""Errors raised for bad input files: each names the file, the row and the fix."""
from __future__ import annotations

from pathlib import Path


class FormatError(ValueError):
    """A file of the clip folder (or an imported file) is malformed.

    The message always names the file, the 1-based line number when the problem is in one row
    (the header is line 1, so the first data row is line 2), what is wrong, and how to fix it.

    Attributes:
        path: the offending file.
        line: 1-based line number in the file, or None when the problem is not in one row.
        problem: what is wrong.
        fix: how to fix it (may be empty).
    """

    def __init__(self, path: str | Path, problem: str, *, line: int | None = None, fix: str = ""):
        self.path = Path(path)
        self.line = line
        self.problem = problem
        self.fix = fix
        where = f"{self.path}" + (f", line {line}" if line is not None else "")
        msg = f"{where}: {problem}"
        if fix:
            msg += f" — fix: {fix}"
        super().__init__(msg)
