"""What the study process keeps of its subjects, on disk rather than in memory.

:class:`PackedSubjects`: each compact result as one pickle in an unnamed temporary
file, as the subjects arrive in any order; :class:`StudyTables`: the study's tables,
made from them in the study's order, in chunks of whole subjects in another.
"""

from __future__ import annotations

import pickle
import tempfile
import weakref
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import pandas as pd

from ..memory import release_freed_memory
from .stats import empty_moments, merge_moments, table_moments
from .subject import (
    MODEL_COLUMNS,
    SUBJECT_TABLES,
    THUMB_GEOMETRY_COLUMNS,
    SubjectResult,
    concat_tables,
    model_geometry,
    thumb_geometry,
)


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


# The study's tables, in the order they are written: name -> the SubjectResult field
# holding a subject's rows (None: made from the subject's model, MODEL_COLUMNS or
# THUMB_GEOMETRY_COLUMNS).
STUDY_TABLES = {
    "max_flexion": "max_flexion",
    "axis_quality": "distances",
    "targets": "targets",
    "truth_axes": "truth_axes",
    "truth_fingertip": "truth_tips",
    "truth_angles": "truth_angles",
    "models": None,
    "thumb_geometry": None,
    "pinch": "pinches",
}
_ALWAYS = {"max_flexion", "axis_quality", "targets", "models"}  # even without rows


def typed_columns(table: pd.DataFrame, schema) -> dict[str, object]:
    """The columns of ``table`` as ``schema`` types them (:func:`fingerfit.io.parquet._typed`)."""
    from ..io.parquet import _typed

    return _typed(table, schema)


def _columns(name: str) -> list[str]:
    field = STUDY_TABLES[name]
    if field is not None:
        return SUBJECT_TABLES[field]
    return MODEL_COLUMNS if name == "models" else THUMB_GEOMETRY_COLUMNS


def _rows(subject: SubjectResult, name: str) -> pd.DataFrame | None:
    """A subject's rows of table ``name`` (None: the table does not apply to it)."""
    field = STUDY_TABLES[name]
    if field is not None:
        return getattr(subject, field)
    if name == "models":
        return model_geometry(subject)
    return thumb_geometry(subject) if "thumb" in subject.model.fingers else None


class StudyTables(Mapping):
    """The study's tables, kept in an unnamed temporary file in chunks of whole subjects.

    As each subject arrives (:meth:`add`, in any order) its rows of every table are
    pickled to the file and taken out of its result. Once all have
    arrived, :meth:`finish` joins them in the study's order into chunks of ``chunk``
    whole subjects, text columns categorical (categories sorted as text sorts), each
    chunk pickled to the file. This process keeps file offsets, not rows: the
    statistics read the chunks one at a time (:meth:`chunks`), the CSV files are
    written chunk by chunk, and a whole table is made only when asked for
    (``tables[name]``, e.g. to draw a figure).

    A mapping (after :meth:`finish`): name -> the whole table, rows in the subjects'
    order, text columns categorical (``str`` operations need ``.astype(str)``). Its
    names: those of :data:`STUDY_TABLES` that apply (the truth tables when a subject has
    ground truth, ``thumb_geometry`` with a thumb, ``pinch`` when there are pinch rows).

    Parameters
    ----------
    folder : Path, optional
        Where the temporary file is made (default: the system's temporary folder).
    chunk : int
        Subjects per chunk.
    """

    def __init__(
        self, folder: Path | None = None, chunk: int = 32, datasets: Path | None = None
    ) -> None:
        self._datasets = datasets
        #: table -> subject -> the Parquet file of its rows written by :meth:`add`
        self.written: dict[str, dict[str, Path]] = {}
        self._file = tempfile.TemporaryFile(prefix=".fingerfit-tables-", dir=folder)
        weakref.finalize(self, self._file.close)
        self._chunk = chunk
        self._subjects: dict[int, tuple[int, int]] = {}  # order -> span of its rows
        self._spans: dict[str, list[tuple[int, int]]] = {k: [] for k in STUDY_TABLES}
        self._applies = set(_ALWAYS)
        self._names: list[str] = []

    def _write(self, data: bytes) -> tuple[int, int]:
        end = self._file.seek(0, 2)
        self._file.write(data)
        return end, len(data)

    def _read(self, span: tuple[int, int]) -> object:
        self._file.seek(span[0])
        return pickle.loads(self._file.read(span[1]))

    def add(self, order: int, result: SubjectResult) -> SubjectResult:
        """Take a subject's rows; its result without them (its table fields None).

        ``order``: the subject's place in the study (see :meth:`finish`).
        """
        rows = {}
        for name in STUDY_TABLES:
            table = _rows(result, name)
            if table is None:
                continue
            if name != "pinch":  # a pinch table only with pinch rows
                self._applies.add(name)
            if not table.empty:
                self._applies.add(name)
                rows[name] = table
        self._subjects[order] = self._write(pickle.dumps(rows, pickle.HIGHEST_PROTOCOL))
        if self._datasets is not None:
            for name, table in rows.items():
                self._write_dataset_part(name, table[_columns(name)])
        return replace(result, **dict.fromkeys(SUBJECT_TABLES))

    def _write_dataset_part(self, name: str, table: pd.DataFrame) -> None:
        """A subject's rows of table ``name`` as ``<datasets>/<name>.parquet/subject=<id>/
        part-0.parquet`` now (:func:`~fingerfit.io.parquet.write_partitioned`'s layout);
        the study checks the column types once all have arrived (:func:`~.study.
        _write_tables`)."""
        from ..io.parquet import STUDY_TABLE, TABLE_KEY, ParquetSink, TableMeta, table_schema

        subjects = table["subject"].astype(str).unique()
        if len(subjects) != 1 or "/" in subjects[0] or subjects[0] in ("", ".", ".."):
            return  # left to the study's final pass, which names the problem
        value = str(subjects[0])
        part = table.drop(columns=["subject"])
        meta = TableMeta(STUDY_TABLE, time_units=None, extra={TABLE_KEY: name})
        assert self._datasets is not None
        path = self._datasets / f"{name}.parquet" / f"subject={value}" / "part-0.parquet"
        schema = table_schema([part])
        with ParquetSink(path, meta, schema=schema) as sink:
            sink.write(typed_columns(part, schema))
        self.written.setdefault(name, {})[value] = path

    def finish(self, orders: Iterable[int]) -> StudyTables:
        """Join the rows of the subjects at ``orders`` (given to :meth:`add`), in that
        order, into the study's tables; returns ``self``."""
        pending: list[dict] = []
        for order in orders:
            pending.append(self._read(self._subjects[order]))
            if len(pending) == self._chunk:
                self._store(pending)
        self._store(pending)
        self._names = [k for k in STUDY_TABLES if k in self._applies]
        release_freed_memory()
        return self

    def _store(self, pending: list[dict]) -> None:
        for name in STUDY_TABLES:
            parts = [rows[name] for rows in pending if name in rows]
            if parts:
                chunk = _categorical(concat_tables(parts, _columns(name)))
                self._spans[name].append(self._write(pickle.dumps(chunk, pickle.HIGHEST_PROTOCOL)))
        pending.clear()

    def chunks(self, name: str) -> Iterator[pd.DataFrame]:
        """The chunks of table ``name`` in order (none when it has no rows or does not
        apply), one at a time: each a table of up to ``chunk`` whole subjects."""
        for span in self._spans.get(name, []):
            yield self._read(span)  # type: ignore[misc]

    def moments(
        self,
        name: str,
        keys: list[str],
        values: list[str],
        prepare: Callable[[pd.DataFrame], pd.DataFrame] | None = None,
    ) -> pd.DataFrame:
        """:func:`~.stats.table_moments` of table ``name`` (count, mean, sum of squared
        deviations, min, max of ``values`` per group of ``keys``), gathered chunk by chunk:
        the whole table is never made.

        ``prepare``: applied to each chunk first (a filter, a new column, or a pivot whose
        rows lie within one subject).
        """
        parts = []
        for chunk in self.chunks(name):
            c = chunk if prepare is None else prepare(chunk)
            if len(c):
                parts.append(table_moments(c, keys, values))
        return merge_moments(pd.concat(parts)) if parts else empty_moments(keys, values)

    def empty(self, name: str) -> pd.DataFrame:
        """Table ``name`` without rows (its columns, with their types when it has rows)."""
        for chunk in self.chunks(name):
            return chunk.iloc[:0]
        return concat_tables([], _columns(name))

    def __getitem__(self, name: str) -> pd.DataFrame:
        if name not in self._names:
            raise KeyError(name)
        return _join_categorical(list(self.chunks(name)), _columns(name))

    def __contains__(self, name: object) -> bool:  # without making the table
        return name in self._names

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __getstate__(self) -> dict:
        raise TypeError("StudyTables holds an open temporary file and cannot be pickled")


def study_tables(subjects: Iterable[SubjectResult], folder: Path | None = None) -> StudyTables:
    """The :class:`StudyTables` of results at hand, in their order."""
    tables = StudyTables(folder)
    n = 0
    for n, s in enumerate(subjects, 1):
        tables.add(n - 1, s)
    return tables.finish(range(n))
