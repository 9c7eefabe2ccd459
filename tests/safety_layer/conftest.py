"""Shared, module-scoped fixtures for the safety-layer tests (sims are slow to build)."""

from __future__ import annotations

import pytest

from distgprl.sim.tasks.dbm import DBMSim


@pytest.fixture(scope="module")
def model_sim():
    sim = DBMSim()
    yield sim
    sim.close()
