"""The simulated tasks and their registry (``TASKS``, :func:`get_task`)."""

from __future__ import annotations

from distgprl.data import check_task_name
from distgprl.sim.tasks.base import (
    DEMO_DIR,
    EVALUATION_SEED,
    TRAINING_CURVE_SEED,
    SegmentResult,
    TaskConfig,
    TaskSim,
    TaskSpec,
)
from distgprl.sim.tasks.dbm import DBMSim, sample_dbm_tc
from distgprl.sim.tasks.dbm import engagement_time as _dbm_engagement
from distgprl.sim.tasks.dcp import DCPSim, sample_dcp_tc
from distgprl.sim.tasks.dcp import engagement_time as _dcp_engagement

TASKS: dict[str, TaskSpec] = {
    "dcp": TaskSpec(
        name="dcp",
        title="Dynamic cube pushing",
        demo_path=DEMO_DIR / "dcp.csv",
        varied_demo_dir=DEMO_DIR / "dcp_varied",
        nominal_tc=TaskConfig(),
        interaction_time=_dcp_engagement() / DCPSim.demo_duration,
        goal="push the drifting cube with the shovel until its centre lies in the goal rectangle",
        sampler=sample_dcp_tc,
        make_sim=DCPSim,
    ),
    "dbm": TaskSpec(
        name="dbm",
        title="Dynamic bar manipulation",
        demo_path=DEMO_DIR / "dbm.csv",
        varied_demo_dir=DEMO_DIR / "dbm_varied",
        nominal_tc=TaskConfig(),
        interaction_time=_dbm_engagement() / DBMSim.demo_duration,
        goal="hook the conveyed target bar by its handle and lift it 12 cm clear of the conveyor",
        sampler=sample_dbm_tc,
        make_sim=DBMSim,
    ),
}
"""Task registry: name -> :class:`TaskSpec`."""


def get_task(name: str) -> TaskSpec:
    """The task called ``name``; raises :class:`UserInputError` listing the valid names."""
    return TASKS[check_task_name(name)]


__all__ = [
    "EVALUATION_SEED",
    "TASKS",
    "TRAINING_CURVE_SEED",
    "DBMSim",
    "DCPSim",
    "SegmentResult",
    "TaskConfig",
    "TaskSim",
    "TaskSpec",
    "get_task",
]
