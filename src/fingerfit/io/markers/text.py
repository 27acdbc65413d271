"""The text of a marker file: its lines split into tab-separated cells, and its data
lines decoded as numbers with the line and column of any bad one named.

Shared by the TRC and the Qualisys TSV readers; both are tab-separated text with a few
header lines and one frame per line. :func:`data_block` parses plain data with Arrow
(:func:`fingerfit.io.fastcsv.block_parser`) and anything else with the exact,
line-numbered parser (:func:`data_cells`, :func:`numbers`), which decides and names
every problem; both give the same numbers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import FingerfitError, shown
from ..textfile import read_text

#: Cells read as a missing sample (case-insensitive, after stripping blanks).
MISSING_CELLS = ("", "nan")
#: The same as spelled in files, for the fast path (any other spelling takes the exact one).
_MISSING_SPELLED = ("", "nan", "NaN", "NAN", "Nan")


def data_block(
    lines: list[str], first: int, columns: list[str], path: Path
) -> tuple[np.ndarray, np.ndarray]:
    """The data lines from index ``first`` on as numbers.

    Parameters
    ----------
    lines : list of str
        The file's lines (:func:`read_lines`).
    first : int
        Index of the first data line (blank lines before it are skipped).
    columns : list of str
        Each field's name, for messages; every line has this many fields (a trailing
        empty one allowed).
    path : Path

    Returns
    -------
    values : ndarray, shape (n, len(columns))
        Floats; a missing cell (:data:`MISSING_CELLS`) NaN.
    line_numbers : ndarray of int, shape (n,)
        1-based file line of each row.

    Raises
    ------
    FingerfitError
        See :func:`data_cells` and :func:`numbers`.
    """
    while first < len(lines) and not lines[first].strip():
        first += 1
    fast = _plain_block(lines[first:], columns)
    if fast is not None:
        return fast, np.arange(first + 1, first + 1 + fast.shape[0])
    cells, rows = data_cells(lines, first, len(columns), path)
    return numbers(cells, rows, columns, path), rows


def _plain_block(body: list[str], columns: list[str]) -> np.ndarray | None:
    """Plain data lines parsed by Arrow, or None when the exact parser must judge them
    (an empty line, a field count that differs, a cell Arrow does not take as a number,
    a NaN or infinity spelled otherwise)."""
    from ..fastcsv import NotPlain, block_parser

    if not body:
        return None
    names = [f"c{i}" for i in range(len(columns))]
    try:
        n_rows, cols = block_parser(names, delimiter="\t", missing=_MISSING_SPELLED)(
            "\n".join(body).encode("utf-8")
        )
    except NotPlain:
        return None
    if n_rows != len(body):  # Arrow skipped an empty line
        return None
    return np.column_stack([cols[n] for n in names])


def read_lines(path: Path) -> list[str]:
    """The file's lines without their ends (``\\n``, ``\\r\\n``), UTF-8.

    Raises
    ------
    FingerfitError
        The file cannot be read, or is not UTF-8 text (naming the line).
    """
    text = read_text(path)
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def split_cells(line: str) -> list[str]:
    """A line's tab-separated cells, blanks stripped."""
    return [c.strip() for c in line.split("\t")]


def data_cells(
    lines: list[str], first: int, n_fields: int, path: Path, what: str = "fields"
) -> tuple[np.ndarray, np.ndarray]:
    """The data lines from index ``first`` on as a ``(n, n_fields)`` array of text.

    Blank lines are skipped. A line may end in empty cells beyond ``n_fields`` (a
    trailing tab); a line with fewer fields, or with anything in a cell beyond them, is
    an error.

    Returns
    -------
    cells : ndarray of str, shape (n, n_fields)
    line_numbers : ndarray of int, shape (n,)
        1-based file line of each row.
    """
    rows: list[list[str]] = []
    numbers: list[int] = []
    for i in range(first, len(lines)):
        line = lines[i]
        if not line.strip():
            continue
        cells = split_cells(line)
        if len(cells) != n_fields:
            extra = cells[n_fields:]
            if len(cells) < n_fields or any(extra):
                raise FingerfitError(
                    f"{len(cells) if len(cells) < n_fields else n_fields + len(extra)} "
                    f"{what}, expected {n_fields} (truncated or misaligned line?)",
                    path=path,
                    line=i + 1,
                )
            cells = cells[:n_fields]
        rows.append(cells)
        numbers.append(i + 1)
    if not rows:
        return np.zeros((0, n_fields), dtype=str), np.zeros(0, dtype=np.int64)
    return np.array(rows, dtype=str), np.array(numbers, dtype=np.int64)


def numbers(
    cells: np.ndarray, line_numbers: np.ndarray, columns: list[str], path: Path
) -> np.ndarray:
    """Decode a block of cells as floats; ``MISSING_CELLS`` become NaN.

    Parameters
    ----------
    cells : ndarray of str, shape (n, k)
    line_numbers : ndarray of int, shape (n,)
        File line of each row, for the message.
    columns : list of str, length k
        Each column's name, for the message.
    path : Path

    Returns
    -------
    ndarray, shape (n, k)

    Raises
    ------
    FingerfitError
        The first cell (by line) that is not a number, or is infinite, naming its line
        and column.
    """
    if cells.size == 0:
        return np.zeros(cells.shape)
    low = np.char.lower(cells)
    missing = np.isin(low, MISSING_CELLS)
    text = np.where(missing, "nan", cells)
    bad = np.char.find(text, "_") >= 0  # float() takes 1_000; no tracker writes it
    values = None
    if not bad.any():
        try:
            values = text.astype(float)
        except ValueError:
            values = None
    if values is None:
        conv = pd.DataFrame(text).apply(lambda c: pd.to_numeric(c, errors="coerce"))
        values = conv.to_numpy(dtype=float)
        bad |= np.isnan(values) & ~missing
    bad |= np.isinf(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        word = "a finite number" if np.isinf(values[r, c]) else "a number"
        raise FingerfitError(
            f"must be {word}, not '{shown(cells[r, c])}'",
            path=path,
            line=int(line_numbers[r]),
            field=columns[c],
        )
    return values
