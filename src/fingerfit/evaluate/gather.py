"""What the study process keeps of its subjects while they arrive, in any order.

:class:`PackedSubjects`: each compact result as one pickle in an unnamed temporary
file; :class:`StudyTables`: their rows of the study's tables, joined as they come.
"""

from __future__ import annotations

import pickle
import tempfile
import weakref
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..memory import release_freed_memory
from .subject import SUBJECT_TABLES, SubjectResult, concat_tables


class PackedSubjects(Sequence):
    """A study's subjects, each kept as one pickle in an anonymous temporary file; every
    access makes a fresh :class:`SubjectResult` from it.

    Holding a thousand subjects costs this process a file offset each, not their
    pickles (about 20 KB each with four fingers) nor the ~1500 Python objects of each
    model and session. The file is made in ``folder`` (default: the system's temporary
    folder; :func:`run_study` uses the output folder's parent, where its staging folder
    is, so the pickles go to the disk the user chose and not to a RAM-backed /tmp). It
    has no name on Linux and is removed by the operating system when it is closed, at
    the latest when this object goes.

    Read-only: a subject changed after access is not stored back. Not for several
    threads at once (reads seek one shared file).
    """

    def __init__(
        self, subjects: list[SubjectResult] | None = None, folder: Path | None = None
    ) -> None:
        self._file = tempfile.TemporaryFile(prefix=".fingerfit-subjects-", dir=folder)
        weakref.finalize(self, self._file.close)  # closed with this object, quietly
        self._spans: list[tuple[int, int]] = []  # (offset, bytes) of each pickle
        self._end = 0
        for s in subjects or []:
            self.append(s)

    def append(self, subject: SubjectResult | bytes) -> None:
        """Keep a subject (or its pickle) after the others."""
        if not isinstance(subject, bytes):
            subject = pickle.dumps(subject, protocol=pickle.HIGHEST_PROTOCOL)
        self._file.seek(self._end)
        self._file.write(subject)
        self._spans.append((self._end, len(subject)))
        self._end += len(subject)

    def select(self, positions: Sequence[int]) -> None:
        """Keep the subjects at ``positions`` (indices into the current order), in that
        order, and drop the others (no pickle is moved)."""
        self._spans = [self._spans[k] for k in positions]

    def __len__(self) -> int:
        return len(self._spans)

    def _load(self, k: int) -> SubjectResult:
        start, size = self._spans[k]
        self._file.seek(start)
        return pickle.loads(self._file.read(size))

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self._load(k) for k in range(len(self))[i]]
        return self._load(range(len(self))[i])

    def __iter__(self) -> Iterator[SubjectResult]:
        for k in range(len(self)):
            yield self._load(k)

    def __getstate__(self) -> dict:
        raise TypeError("PackedSubjects holds an open temporary file and cannot be pickled")


def _categorical(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with each text column categorical (categories sorted, as text sorts).

    A study's text columns (subject, finger, joint, recording, ...) repeat a few hundred
    values: as categories its tables take a third of the memory of Arrow text, and
    ``pd.concat`` of Arrow text would keep one small chunk per input table.
    """
    text = [c for c, t in table.dtypes.items() if isinstance(t, pd.StringDtype)]
    if not text:
        return table
    return table.astype(dict.fromkeys(text, "category"))


def _join_categorical(frames: list[pd.DataFrame], columns: list[str]) -> pd.DataFrame:
    """Concatenate tables whose text columns are categorical with their own categories:
    the result's categories are the union, sorted (``pd.concat`` would fall back to
    Python objects)."""
    from pandas.api.types import union_categoricals

    frames = [f for f in frames if not f.empty]
    if len(frames) <= 1:
        return concat_tables(frames, columns)

    def categorical(x: pd.Series) -> pd.Series:  # a chunk's column may be all missing
        return x if isinstance(x.dtype, pd.CategoricalDtype) else x.astype("str").astype("category")

    union = {
        c: pd.CategoricalDtype(
            union_categoricals(
                [categorical(f[c]) for f in frames], sort_categories=True, ignore_order=True
            ).categories
        )
        for c in columns
        if any(isinstance(f[c].dtype, pd.CategoricalDtype) for f in frames)
    }
    if union:
        frames = [f.astype(union) for f in frames]
    return concat_tables(frames, columns)


class StudyTables:
    """The per-subject rows of a study, gathered as the subjects arrive, in any order.

    A subject's tables (one small DataFrame each, a few KB of rows but tens of KB of
    pandas overhead) are taken out of its result; every ``chunk`` subjects the ones
    held are joined into one DataFrame per table, so memory grows by the rows alone,
    and each row is copied twice in all (into its chunk, then into the study's table).
    :meth:`tables` gives the same tables as concatenating every subject's, in the
    subjects' order.

    Parameters
    ----------
    chunk : int
        Subjects whose tables are held as separate DataFrames before they are joined.
    """

    def __init__(self, chunk: int = 32) -> None:
        self._chunk = chunk
        self._pending: dict[str, list[pd.DataFrame]] = {k: [] for k in SUBJECT_TABLES}
        self._joined: dict[str, list[pd.DataFrame]] = {k: [] for k in SUBJECT_TABLES}
        self._rows: dict[str, list[tuple[int, int]]] = {k: [] for k in SUBJECT_TABLES}
        self._present: set[str] = set()  # tables some subject has (not None)

    def add(self, order: int, result: SubjectResult) -> SubjectResult:
        """Take a subject's tables; the result without them (its table fields None).

        ``order``: the subject's place in the study (its rows come out in this order).
        """
        for key, columns in SUBJECT_TABLES.items():
            table = getattr(result, key)
            if table is None:
                continue
            self._present.add(key)
            if table.empty:
                continue
            self._pending[key].append(table[columns])
            self._rows[key].append((order, len(table)))
            if len(self._pending[key]) >= self._chunk:
                self._join(key)
        return replace(result, **dict.fromkeys(SUBJECT_TABLES))

    def _join(self, key: str) -> None:
        if self._pending[key]:
            joined = concat_tables(self._pending[key], SUBJECT_TABLES[key])
            self._joined[key].append(_categorical(joined))
            self._pending[key] = []

    def tables(self) -> dict[str, pd.DataFrame | None]:
        """SubjectResult field -> the study's table, rows in the subjects' order
        (None: no subject has the table). Its text columns are categorical, categories
        sorted (``str`` operations need ``.astype(str)``; grouping, sorting, comparing
        and writing give what text columns give)."""
        out: dict[str, pd.DataFrame | None] = {}
        for key, columns in SUBJECT_TABLES.items():
            if key not in self._present:
                out[key] = None
                continue
            self._join(key)
            joined = _join_categorical(self._joined[key], columns)
            self._joined[key] = [joined]  # the chunks go before the reordering's copy
            rows = self._rows[key]
            given = [o for o, _n in rows]
            if given != sorted(given):  # arrived in another order
                starts = np.cumsum([0] + [n for _o, n in rows])
                order = np.argsort(given, kind="stable")
                take = np.concatenate([np.arange(starts[i], starts[i] + rows[i][1]) for i in order])
                joined = joined.take(take).reset_index(drop=True)
                self._joined[key] = [joined]
                self._rows[key] = [rows[i] for i in order]
            out[key] = joined
        release_freed_memory()  # the chunks' and the reordering's copies
        return out
