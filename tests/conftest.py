"""Shared simulated subjects (built once per test session)."""

from __future__ import annotations

import copy
import dataclasses
import functools

import pytest

from fingerfit.simulate import SimConfig, SimulatedSubject, simulate_subject


@functools.cache
def _simulated(kind: str, seed: int, fingers: tuple[str, ...]) -> SimulatedSubject:
    config = SimConfig.exact(fingers=fingers) if kind == "exact" else SimConfig(fingers=fingers)
    return simulate_subject(config, seed)


def subject(kind: str, seed: int, fingers: tuple[str, ...] = ("index",)) -> SimulatedSubject:
    """A cached simulated subject: ``kind`` is ``exact`` or ``realistic``.

    Each call gets its own :class:`~fingerfit.session.Session` object (the recordings are
    shared): writing the subject (``write_subject`` sets ``session.path``) or replacing a
    session field in one test does not reach the others (a session with a path prefixes
    its plausibility messages with its landmarks file).
    """
    sim = _simulated(kind, seed, fingers)
    return dataclasses.replace(sim, session=copy.copy(sim.session))


@pytest.fixture(scope="session")
def exact_subject() -> SimulatedSubject:
    return subject("exact", 11)


@pytest.fixture(scope="session")
def realistic_subject() -> SimulatedSubject:
    return subject("realistic", 2)
