"""One CSV parser and validator shared by every reader and importer.

:class:`CsvTable` reads a whole file with the ``csv`` module, checks the header, and converts columns
to numpy arrays in one vectorised step. Every check reports the file, the 1-based line (the header is
line 1) and a fix as a :class:`FormatError`, never a raw numpy or csv traceback.
"""

from __future__ import annotations

import csv
import difflib
import io
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np

from .atomic import atomic_write_text
from .errors import FormatError
from .tables import MAX_FRAMES, MAX_FRAMES_TEXT, UNIT_TOLERANCE

T = TypeVar("T")


def closest(name: str, choices: Iterable[str]) -> str | None:
    """The entry of ``choices`` closest to ``name`` (difflib), or None when nothing is close."""
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return match[0] if match else None


#: the file type a fix names, by suffix (a YAML file is not "saved as CSV")
FILE_TYPES = {".csv": "CSV", ".yaml": "YAML", ".yml": "YAML", ".json": "JSON", ".xml": "XML", ".txt": "text"}


def file_type(path: str | Path) -> str:
    """``CSV``, ``YAML``, ``JSON``, ``XML`` or ``text``: what a fix calls the file, from its suffix."""
    return FILE_TYPES.get(Path(path).suffix.lower(), "text")


def read_text(path: str | Path) -> str:
    """Read a UTF-8 text file (a BOM is dropped); ``FormatError`` when missing or not text (its fix names
    the file's type: :func:`file_type`)."""
    path = Path(path)
    if not path.is_file():
        problem = "is a folder, not a file" if path.is_dir() else "file not found"
        raise FormatError(path, problem, fix=f"create {path.name} or pass the right path")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as err:
        raise FormatError(path, f"not UTF-8 text ({err.reason})",
                          fix=f"save the file as UTF-8 {file_type(path)}") from None


class CsvTable:
    """The rows of one CSV file as strings, with their line numbers, plus validated column accessors.

    Attributes:
        path: the file.
        header: column names as written (whitespace stripped).
        lines: ``(N,) int64``, 1-based line number of each data row.
    """

    def __init__(self, path: Path, header: list[str], rows: list[list[str]], lines: list[int]):
        self.path = path
        self.header = header
        self._rows = rows
        self.lines = np.asarray(lines, dtype=np.int64)
        self._index = {name: i for i, name in enumerate(header)}

    # -------------------------------------------------------------------------------------- reading
    @classmethod
    def read(
        cls,
        path: str | Path,
        columns: Sequence[str],
        *,
        optional: Sequence[str] = (),
        ignore_case: bool = False,
        allow_empty: bool = True,
        skipped: list[FormatError] | None = None,
    ) -> CsvTable:
        """Parse ``path`` and check that its header holds every name of ``columns``.

        Args:
            path: the CSV file.
            columns: required column names (extra columns are kept and may be read by name).
            optional: columns that may be absent (only used to describe the format in messages).
            ignore_case: match column names case-insensitively (for outside formats); the names of
                the returned table are then those of ``columns``/``optional``.
            allow_empty: accept a file with a header and no data rows.
            skipped: when a list is given, rows with the wrong number of fields are dropped (their errors
                appended to it) instead of failing the whole file.
        """
        path = Path(path)
        text = read_text(path)
        try:
            records = list(_records(csv.reader(io.StringIO(text, newline=""), strict=True)))
        except csv.Error as err:
            raise FormatError(path, f"not valid CSV ({err})", fix="check quotes and separators") from None
        expected = ",".join(columns)
        if not records:
            raise FormatError(path, "empty file", line=1, fix=f"write the header line: {expected}")
        header_line, header = records[0]
        header = [name.strip() for name in header]
        header = _match_header(path, header, columns, optional, ignore_case, header_line)
        rows = [row for _, row in records[1:]]
        lines = [line for line, _ in records[1:]]
        header, rows = _drop_unnamed_columns(path, header, rows, header_line)
        table = cls(path, header, rows, lines)
        table._check_field_counts(skipped)
        if not rows and not allow_empty:
            raise FormatError(path, "no data rows", line=2, fix="add at least one data row")
        return table

    def _check_field_counts(self, skipped: list[FormatError] | None = None) -> None:
        width = len(self.header)
        bad = [i for i, row in enumerate(self._rows) if len(row) != width]
        errors = [
            self.error(
                i,
                f"{len(self._rows[i])} fields, but the header has {width}",
                fix=f"write exactly {width} comma-separated values: {','.join(self.header)}",
            )
            for i in bad[: 1 if skipped is None else None]
        ]
        if errors and skipped is None:
            raise errors[0]
        if errors:
            skipped.extend(errors)
            keep = sorted(set(range(len(self._rows))) - set(bad))
            self._rows = [self._rows[i] for i in keep]
            self.lines = self.lines[keep]

    def without_line(self, line: int) -> CsvTable:
        """A copy without the data row at 1-based file ``line`` (KeyError when no row starts there)."""
        hits = np.flatnonzero(self.lines == line)
        if not hits.size:
            raise KeyError(line)
        i = int(hits[0])
        return CsvTable(self.path, self.header, self._rows[:i] + self._rows[i + 1 :],
                        [int(v) for v in np.delete(self.lines, i)])

    def extra_columns(self, known: Sequence[str]) -> dict[str, list[str]]:
        """The text of every column not in ``known``, ``{name: one string per row}``, in file order."""
        return {c: self.strings(c) for c in self.header if c not in known}

    # -------------------------------------------------------------------------------------- columns
    def __len__(self) -> int:
        return len(self._rows)

    def has(self, column: str) -> bool:
        """Whether the file has ``column``."""
        return column in self._index

    def strings(self, column: str) -> list[str]:
        """The stripped text of ``column``, one entry per row."""
        i = self._index[column]
        return [row[i].strip() for row in self._rows]

    def empty_mask(self, column: str) -> np.ndarray:
        """``(N,) bool``, True where ``column`` is empty."""
        return np.array([s == "" for s in self.strings(column)], dtype=bool)

    def floats(self, column: str, *, allow_empty: bool = False) -> np.ndarray:
        """``column`` as ``(N,) float64``; empty cells become NaN (only if ``allow_empty``).

        ``FormatError`` for non-numeric text, for ``nan``/``inf`` written out, and for empty cells
        unless allowed.
        """
        texts = self.strings(column)
        empty = np.array([s == "" for s in texts], dtype=bool)
        if not allow_empty:
            self.check(empty, f"{column} is empty", fix=f"write a number in column {column}")
        try:
            values = np.array([s or "nan" for s in texts], dtype=np.float64)
        except ValueError:
            values = self._parse_one_by_one(texts, column)
        self.check(
            ~np.isfinite(values) & ~empty,
            lambda i: f"{column} is {texts[i]!r}",
            fix=f"write a finite number in column {column}" + (" or leave it empty" if allow_empty else ""),
        )
        return values

    def _parse_one_by_one(self, texts: list[str], column: str) -> np.ndarray:
        values = np.empty(len(texts))
        for i, text in enumerate(texts):
            try:
                values[i] = float(text or "nan")
            except ValueError:
                raise self.error(
                    i, f"{column} is not a number: {text!r}", fix=f"write a number in column {column}"
                ) from None
        return values

    def ints(self, column: str) -> np.ndarray:
        """``column`` as ``(N,) int64``; ``FormatError`` for empty, non-numeric or fractional cells."""
        values = self.floats(column)
        self.check(
            values != np.round(values),
            lambda i: f"{column} is not an integer: {values[i]:g}",
            fix=f"write a whole number in column {column}",
        )
        self.check(
            np.abs(values) > 2**53,
            lambda i: f"{column} is too large: {values[i]:g}",
            fix=f"write a whole number below 2^53 in column {column}",
        )
        return values.astype(np.int64)

    def choices(self, column: str, allowed: Sequence[str]) -> np.ndarray:
        """``column`` as ``(N,) str``; ``FormatError`` naming the valid values for anything else."""
        texts = np.array(self.strings(column), dtype=str) if len(self) else np.empty(0, "<U1")
        bad = ~np.isin(texts, list(allowed))

        def problem(i: int) -> str:
            hint = closest(str(texts[i]), allowed)
            return f"unknown {column} {str(texts[i])!r}" + (f" (did you mean {hint!r}?)" if hint else "")

        self.check(bad, problem, fix=f"use one of: {', '.join(allowed)}")
        return texts

    # --------------------------------------------------------------------------------------- checks
    def error(self, row: int, problem: str, fix: str = "") -> FormatError:
        """A :class:`FormatError` for data row ``row`` (0-based), naming its line in the file."""
        return FormatError(self.path, problem, line=int(self.lines[row]), fix=fix)

    def check(self, bad: np.ndarray, problem: str | Callable[[int], str], fix: str = "") -> None:
        """Raise for the first row where ``bad`` is True; ``problem`` may depend on the row."""
        hits = np.flatnonzero(bad)
        if hits.size:
            i = int(hits[0])
            raise self.error(i, problem(i) if callable(problem) else problem, fix)

    def check_frames(
        self, frame: np.ndarray, *, n_frames: int | None = None, unique: bool = True, column: str = "frame"
    ) -> None:
        """Frames must be ``>= 0``, ``< n_frames`` when given, and (if ``unique``) not repeated."""
        self.check(
            frame < 0, lambda i: f"negative {column} {frame[i]}", fix="frames are zero-based indices >= 0"
        )
        if n_frames is not None:
            self.check(
                frame >= n_frames,
                lambda i: f"{column} {frame[i]} is beyond the video ({n_frames} frames)",
                fix=f"frames must be in 0..{n_frames - 1}; check the clip's video or n_frames",
            )
        else:  # no length known: still no frame beyond any video (a table's last frame sizes arrays)
            self.check(
                frame >= MAX_FRAMES,
                lambda i: f"{column} {frame[i]} is beyond any video ({MAX_FRAMES_TEXT})",
                fix="frames are zero-based indices of the clip's video frames",
            )
        if unique:
            self.check(
                duplicated(frame),
                lambda i: f"duplicate {column} {frame[i]}",
                fix=f"keep one row per {column}",
            )

    def unit_coords(self, xy: np.ndarray, columns: Sequence[str], fix: str = "") -> np.ndarray:
        """Check normalised ``(N, k)`` coordinates are in ``[0, 1]`` (NaN ignored) and clip them."""
        outside = (xy < -UNIT_TOLERANCE) | (xy > 1 + UNIT_TOLERANCE)
        for j, column in enumerate(columns):
            self.check(
                outside[:, j],
                lambda i, j=j, c=column: f"{c} = {xy[i, j]:g} is outside [0, 1]",
                fix=fix or "coordinates are normalised: divide pixels by the image width/height",
            )
        return np.clip(xy, 0.0, 1.0)


def parse_rows(table: CsvTable, parse: Callable[[CsvTable], T], skipped: list[FormatError] | None = None) -> T:
    """``parse(table)``; with a ``skipped`` list, a row that fails a check is dropped (its error appended to
    ``skipped``) and the rest parsed again, so one bad row does not lose the file. Header errors still raise."""
    while True:
        try:
            return parse(table)
        except FormatError as err:
            if skipped is None or err.line is None:
                raise
            try:
                table = table.without_line(err.line)
            except KeyError:
                raise err from None
            skipped.append(err)


def _drop_unnamed_columns(
    path: Path, header: list[str], rows: list[list[str]], line: int
) -> tuple[list[str], list[list[str]]]:
    """Drop columns without a name (a trailing comma, as spreadsheets write) when they hold nothing."""
    unnamed = [i for i, name in enumerate(header) if name == ""]
    if not unnamed:
        return header, rows
    for row in rows:
        if any(i < len(row) and row[i].strip() for i in unnamed):
            raise FormatError(path, f"column {unnamed[0] + 1} has no name but holds values", line=line,
                              fix="give every column a name in the header")
    keep = [i for i in range(len(header)) if i not in unnamed]
    return [header[i] for i in keep], [[row[i] for i in keep if i < len(row)] + row[len(header):] for row in rows]


def _match_header(
    path: Path,
    header: list[str],
    columns: Sequence[str],
    optional: Sequence[str],
    ignore_case: bool,
    line: int,
) -> list[str]:
    """Check the header holds ``columns``; with ``ignore_case`` rename its columns to their spelling."""
    known = [*columns, *optional]
    if ignore_case:
        canonical = {name.lower(): name for name in known}
        header = [canonical.get(name.lower(), name) for name in header]
    duplicates = sorted({name for name in header if header.count(name) > 1})
    if duplicates:
        raise FormatError(
            path, f"duplicate column(s) {duplicates}", line=line, fix="give every column a distinct name"
        )
    missing = [name for name in columns if name not in header]
    if missing:
        unknown = [name for name in header if name not in known]
        hints = [f"rename {u!r} to {m!r}" for m in missing if (u := closest(m, unknown))]
        fix = "; ".join(hints) if hints else f"the header must be: {','.join(columns)}"
        separator = next((sep for sep in (";", "\t", "|") if len(header) == 1 and sep in header[0]), None)
        if separator is not None:
            name = {"\t": "tabs"}.get(separator, repr(separator))
            raise FormatError(
                path,
                f"the columns are separated by {name}, not commas",
                line=line,
                fix=f"save it as comma-separated CSV (header: {','.join(columns)})",
            )
        raise FormatError(
            path,
            f"missing column(s) {missing}; expected {','.join(known)}, found {','.join(header) or '(none)'}",
            line=line,
            fix=fix,
        )
    return header


def _records(reader) -> Iterable[tuple[int, list[str]]]:
    """``(first line, fields)`` of each non-blank record."""
    line = 1
    for row in reader:
        if len(row) > 1 or (row and row[0].strip()):
            yield line, row
        line = reader.line_num + 1


def duplicated(values: np.ndarray) -> np.ndarray:
    """``(N,) bool``, True at every repeat of a value seen earlier in ``values`` (rows may be 2-D)."""
    if len(values) == 0:
        return np.zeros(0, dtype=bool)
    axis = 0 if values.ndim > 1 else None
    _, first = np.unique(values, return_index=True, axis=axis)
    mask = np.ones(len(values), dtype=bool)
    mask[first] = False
    return mask


# ------------------------------------------------------------------------------------------ writing
def format_floats(values: np.ndarray, decimals: int) -> list[str]:
    """Fixed-point text of ``values`` with ``decimals`` digits; NaN becomes an empty cell."""
    fmt = f"{{:.{decimals}f}}"
    return ["" if v != v else fmt.format(v) for v in np.asarray(values, dtype=np.float64).tolist()]


def format_ints(values: np.ndarray) -> list[str]:
    """Text of integer ``values``."""
    return [str(v) for v in np.asarray(values, dtype=np.int64).tolist()]


def write_csv(path: str | Path, header: Sequence[str], columns: Sequence[Sequence[str]]) -> Path:
    """Write ``columns`` (each a sequence of cell texts) under ``header`` atomically, ``\\n`` line ends."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(zip(*columns))
    return atomic_write_text(path, buffer.getvalue())
