"""The paper's evaluation (sections 4-5, Figs. 8-12): axis quality, fingertip error at
maximal flexion and when reaching targets, statistics, figures and the HTML report."""

from .study import StudyResult, run_study

__all__ = ["StudyResult", "run_study"]
