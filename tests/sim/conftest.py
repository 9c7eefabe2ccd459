"""Shared, module-scoped simulations (building one takes about half a second)."""

from __future__ import annotations

import pytest

from distgprl.sim.tasks.dbm import DBMSim
from distgprl.sim.tasks.dcp import DCPSim


@pytest.fixture(scope="module")
def dcp_sim():
    sim = DCPSim()
    yield sim
    sim.close()


@pytest.fixture(scope="module")
def dbm_sim():
    sim = DBMSim()
    yield sim
    sim.close()
