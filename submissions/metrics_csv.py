"""``metrics.csv``: bounded checking (at validation) and bounded, downsampled reading.

A metrics file is one CSV row per line: a header of column names, then one row per
training iteration. Everything about it is bounded by :class:`~submissions.format.Limits`:
bytes (as an archive member), line length, columns, rows and cells (rows x columns).
:func:`check_metrics` refuses a file over any bound; :func:`read_metrics` reads any file
(even one stored before these bounds) within them and downsamples its rows to at most
``max_points`` points, so its result is small by construction.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterator
from dataclasses import dataclass

from submissions.format import METRICS_MEMBER, Limits, Problem

DEFAULT_MAX_POINTS = 500
"""Points per column in a read (the model page's graph is 900 pixels wide)."""
_FIELD = f"archive:{METRICS_MEMBER}"


@dataclass(frozen=True)
class MetricsSeries:
    """Column names and one list of numbers (None: blank or not a number) per column."""

    columns: list[str]
    values: dict[str, list[float | None]]
    rows: int  # data rows in the file (before downsampling)


class _Refused(Exception):
    """A bound was exceeded; carries the problem to report."""

    def __init__(self, problem: Problem) -> None:
        super().__init__(str(problem))
        self.problem = problem


def _problem(expected: str, found: str, message: str) -> Problem:
    return Problem(field=_FIELD, expected=expected, found=found, message=message)


def _lines(data: bytes, limits: Limits) -> Iterator[tuple[int, bytes]]:
    """Each physical line (numbered from 1, line ending removed), within the line and row
    bounds; a line past either raises :class:`_Refused` when it is reached."""
    stream = io.BytesIO(data)
    max_lines = limits.max_metrics_rows + 1  # the header and the rows
    number = 0
    while line := stream.readline(limits.max_metrics_line_bytes + 2):
        number += 1
        if number > max_lines:
            raise _Refused(
                _problem(
                    f"at most {limits.max_metrics_rows} rows",
                    "more",
                    "The metrics file has too many rows.",
                )
            )
        text = line.rstrip(b"\r\n")
        if len(text) > limits.max_metrics_line_bytes:
            raise _Refused(
                _problem(
                    f"lines of at most {limits.max_metrics_line_bytes} bytes",
                    f"line {number} of more",
                    "A line of the metrics file is too long.",
                )
            )
        yield number, text


def _cells(text: bytes, number: int, limits: Limits, strict: bool = True) -> list[str]:
    """The cells of one line; more cells than the column bound are refused (``strict``)
    or cut to the bound."""
    try:
        cells = next(csv.reader([text.decode("utf-8", "replace")]), [])
    except csv.Error as exc:
        raise _Refused(
            _problem("CSV text", f"line {number}: {exc}", "The metrics file is not readable CSV.")
        ) from None
    if len(cells) > limits.max_metrics_columns and not strict:
        return cells[: limits.max_metrics_columns]
    if len(cells) > limits.max_metrics_columns:
        raise _Refused(
            _problem(
                f"at most {limits.max_metrics_columns} columns",
                f"{len(cells)} on line {number}",
                "The metrics file has too many columns.",
            )
        )
    return cells


def _check_header(cells: list[str], limits: Limits) -> None:
    long = [c for c in cells if len(c) > limits.max_metrics_name_chars]
    if long:
        raise _Refused(
            _problem(
                f"column names of at most {limits.max_metrics_name_chars} characters",
                f"a name of {len(long[0])}",
                "A column name of the metrics file is too long.",
            )
        )


def _check_cells(rows: int, columns: int, limits: Limits) -> None:
    if rows * columns > limits.max_metrics_cells:
        raise _Refused(
            _problem(
                f"at most {limits.max_metrics_cells} cells (rows x columns)",
                f"{rows} rows of {columns} columns",
                "The metrics file has too many cells.",
            )
        )


def check_metrics(data: bytes, limits: Limits) -> list[Problem]:
    """Problems of a ``metrics.csv`` over any bound (an empty list when it is within all)."""
    columns = 0
    try:
        for number, text in _lines(data, limits):
            cells = _cells(text, number, limits)
            if number == 1:
                _check_header(cells, limits)
                columns = len(cells)
            else:
                _check_cells(number - 1, columns, limits)
    except _Refused as refused:
        return [refused.problem]
    return []


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _bucket_ends(rows: int, max_points: int) -> list[int]:
    """Exclusive end index of each of at most ``max_points`` consecutive buckets of rows."""
    points = min(rows, max_points)
    return [math.ceil((k + 1) * rows / points) for k in range(points)]


def _bucket_row(lines: list[bytes], width: int, limits: Limits) -> list[str]:
    """Each column's last non-blank cell in a bucket of lines ('' where it has none)."""
    cells = [""] * width
    missing = set(range(width))
    for text in reversed(lines):
        try:
            row = _cells(text, 0, limits, strict=False)
        except _Refused:
            continue
        for index in [i for i in missing if i < len(row) and row[i].strip()]:
            cells[index] = row[index]
            missing.discard(index)
        if not missing:
            break
    return cells


def read_metrics(
    data: bytes, limits: Limits, max_points: int = DEFAULT_MAX_POINTS
) -> MetricsSeries:
    """The columns of a metrics file as numbers, at most ``max_points`` per column.

    Rows are grouped in at most ``max_points`` consecutive buckets (one row each while
    there are no more rows than points); a point is its bucket's last non-blank value of
    the column. Only the lines a point needs are parsed. A file over a bound is read up
    to it (files stored before the bound existed); nothing here raises for bad input.
    """
    header: list[str] = []
    lines: list[bytes] = []
    try:
        for number, text in _lines(data, limits):
            if number == 1:
                header = _cells(text, number, limits, strict=False)
            elif text.strip():
                _check_cells(len(lines) + 1, len(header), limits)
                lines.append(text)
    except _Refused:
        pass
    named: dict[str, int] = {}
    for index, column in enumerate(header):
        if column and column not in named and len(column) <= limits.max_metrics_name_chars:
            named[column] = index
    values: dict[str, list[float | None]] = {c: [] for c in named}
    start = 0
    for end in _bucket_ends(len(lines), max_points) if lines else []:
        row = _bucket_row(lines[start:end], len(header), limits)
        for column, index in named.items():
            values[column].append(_number(row[index]))
        start = end
    return MetricsSeries(columns=list(named), values=values, rows=len(lines))
