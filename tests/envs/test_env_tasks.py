"""`distgprl.envs.tasks`: the glue between environments and task simulations."""

from __future__ import annotations

from distgprl.envs.tasks import hap_robot_id


def test_hap_robot_id_keeps_the_cache_keys_of_the_existing_subspaces():
    """The HAP cache key's robot id is unchanged by the Robot/Task split (revision 0 adds
    nothing): the cached subspaces of both tasks stay valid."""
    assert hap_robot_id("ur5e", "shovel", "dcp", 0) == "ur5e+shovel/dcp/hap-wiring-v1"
    assert hap_robot_id("ur5e", "hook", "dbm", 2) == "ur5e+hook/dbm/hap-wiring-v1/scene-r2"
