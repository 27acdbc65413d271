"""Shared simulated subjects (built once per test session)."""

from __future__ import annotations

import functools

import pytest

from fingerfit.simulate import SimConfig, SimulatedSubject, simulate_subject


@functools.cache
def subject(kind: str, seed: int, fingers: tuple[str, ...] = ("index",)) -> SimulatedSubject:
    """A cached simulated subject: ``kind`` is ``exact`` or ``realistic``."""
    config = SimConfig.exact(fingers=fingers) if kind == "exact" else SimConfig(fingers=fingers)
    return simulate_subject(config, seed)


@pytest.fixture(scope="session")
def exact_subject() -> SimulatedSubject:
    return subject("exact", 11)


@pytest.fixture(scope="session")
def realistic_subject() -> SimulatedSubject:
    return subject("realistic", 2)
