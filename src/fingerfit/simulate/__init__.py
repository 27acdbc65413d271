"""Realistic simulated sessions with ground truth (see ``docs/simulator.md``)."""

from .study import SimConfig, SimulatedSubject, simulate_cohort, simulate_subject, write_subject

__all__ = ["SimConfig", "SimulatedSubject", "simulate_cohort", "simulate_subject", "write_subject"]
