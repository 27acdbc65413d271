"""A simulated session made where the study task runs (large simulated cohorts).

A study of ``N`` simulated subjects needs their session folders (about 34 MB each with
their truth) before it starts; for a cohort of a thousand that is 34 GB and most of an
hour of simulation on one machine. :class:`SimulatedSession` is a study input that
stands for one such session: the study task simulates it on the worker, writes it to
a temporary folder there, and studies that folder exactly like a folder given on the
command line (read, truth, fit, evaluate), then removes it.
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .study import SimConfig, simulate_subject, subject_ids, write_subject


@dataclass(frozen=True)
class SimulatedSession:
    """One simulated subject's session, made on demand (a :class:`SessionSource`).

    Attributes
    ----------
    config : SimConfig
    seed : int
        The subject's seed (:func:`simulate_subject`).
    subject : str
        Its subject ID.
    """

    config: SimConfig
    seed: int
    subject: str

    def __str__(self) -> str:
        return f"simulated {self.subject} (seed {self.seed})"

    @contextlib.contextmanager
    def open(self) -> Iterator[Path]:
        """Simulate, write the session folder (with its truth) to a temporary folder and
        give its path; the folder is removed afterwards."""
        with tempfile.TemporaryDirectory(prefix="fingerfit-sim-") as tmp:
            sim = simulate_subject(self.config, self.seed, self.subject)
            folder = write_subject(sim, Path(tmp) / self.subject)
            del sim  # the study reads the folder: one copy of the frames at a time
            yield folder


def simulated_cohort(config: SimConfig, n_subjects: int, seed: int) -> list[SimulatedSession]:
    """``n_subjects`` sources, subject IDs by :func:`~fingerfit.simulate.study.subject_ids`,
    the seeds of
    :func:`~fingerfit.simulate.simulate_cohort` (subject i: the i-th seed spawned from
    ``seed``); each is simulated only when a study task opens it."""
    seeds = np.random.SeedSequence(seed).spawn(n_subjects)
    return [
        SimulatedSession(config, int(s.generate_state(1)[0]), name)
        for s, name in zip(seeds, subject_ids(n_subjects), strict=True)
    ]
