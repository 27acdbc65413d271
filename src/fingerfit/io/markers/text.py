"""The text of a marker file: its lines split into tab-separated cells, and a block of
cells decoded as numbers with the line and column of any bad one named.

Shared by the TRC and the Qualisys TSV readers; both are tab-separated text with a few
header lines and one frame per line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import FingerfitError, shown
from ..textfile import read_text

#: Cells read as a missing sample (case-insensitive, after stripping blanks).
MISSING_CELLS = ("", "nan")


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
