"""What a study produces: :class:`StudyResult`.

The study (:mod:`.study`) makes it; the report (:mod:`.report`) and the command line
read it. Data flow one way: study -> results <- report.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .gather import StudyTables
from .subject import SessionFailure, SubjectResult


@dataclass
class StudyResult:
    """The study's tables, statistics and output paths.

    ``subjects``: from :func:`~fingerfit.evaluate.study.run_study` a
    :class:`~.gather.PackedSubjects` (compact results); ``tables``: a
    :class:`~.gather.StudyTables` (kept on disk; ``tables[name]`` makes the whole table).
    """

    subjects: Sequence[SubjectResult]
    summary: dict
    tables: StudyTables
    out_dir: Path
    figures: dict[str, Path] = field(default_factory=dict)
    report: Path | None = None
    failures: list[SessionFailure] = field(default_factory=list)
