"""PyBullet body construction: every shape a compound body is given is in the simulation."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest

from distgprl.safety.shapes import Box
from distgprl.sim.bullet import (
    MAX_SHAPES_PER_ARRAY,
    PhysicsConfig,
    create_compound_body,
    make_client,
)


def _row_of_boxes(n: int) -> tuple[Box, ...]:
    """n 2 cm cubes 10 cm apart along y, at z = 0.5 m."""
    return tuple(
        Box(f"box_{k}", np.array([0.0, 0.1 * k, 0.5]), np.eye(3), np.full(3, 0.01))
        for k in range(n)
    )


def _distance_to(client, body, point) -> float:
    shape = client.createCollisionShape(pybullet.GEOM_SPHERE, radius=1e-4)
    probe = client.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape, basePosition=point)
    points = client.getClosestPoints(probe, body, distance=1.0)
    client.removeBody(probe)
    return min(p[8] for p in points) + 1e-4 if points else np.inf


@pytest.mark.parametrize("n", [MAX_SHAPES_PER_ARRAY, MAX_SHAPES_PER_ARRAY + 1, 31, 40])
def test_a_static_compound_body_holds_every_shape(n):
    """Each of the n boxes is 5 cm from a point 5 cm above it (DBM's 31 rollers once lost
    15 of theirs: PyBullet keeps 16 children per shape array and drops the rest silently)."""
    client = make_client(PhysicsConfig())
    try:
        boxes = _row_of_boxes(n)
        body = create_compound_body(client, boxes, (1, 1, 1, 1), origin=np.array([0, 0, 0.5]))
        for box in boxes:
            above = (box.position + np.array([0.0, 0.0, 0.06])).tolist()
            assert _distance_to(client, body, above) == pytest.approx(0.05, abs=1e-6), box.name
        beyond = [0.0, 0.1 * n + 0.06, 0.5]  # 16 cm past the last box's centre
        assert _distance_to(client, body, beyond) == pytest.approx(0.15, abs=1e-6)
    finally:
        client.disconnect()


def test_a_dynamic_compound_body_beyond_one_shape_array_is_refused():
    client = make_client(PhysicsConfig())
    try:
        with pytest.raises(ValueError, match="at most 16 shapes"):
            create_compound_body(
                client, _row_of_boxes(17), (1, 1, 1, 1), origin=np.zeros(3), mass=1.0
            )
    finally:
        client.disconnect()


def test_a_connect_writes_nothing_to_stdout(capfd):
    """PyBullet's ``argv[0]=`` (C printf at connect) stays off file descriptor 1, and what
    was printed before and after still reaches it, in order."""
    from distgprl.sim.bullet import PhysicsConfig, make_client

    print("before", flush=True)
    client = make_client(PhysicsConfig())
    client.disconnect()
    print("after", flush=True)
    out, _ = capfd.readouterr()
    assert out == "before\nafter\n"


def test_importing_the_simulation_and_connecting_prints_nothing_in_a_fresh_process():
    """Nothing pybullet prints at import or connect (``argv[0]=`` on stdout; its ``pybullet
    build time`` banner on stderr, kept off by `distgprl.sim.import_pybullet_quietly`)
    reaches a piped stdout or stderr, whichever module imports the simulation first (in a
    sweep's job process: the sweep)."""
    import subprocess
    import sys

    modules = ("distgprl.sim.tasks.base", "distgprl.sim.robot", "distgprl.sim.bullet")
    for module in (*modules, "distgprl.experiments.sweep"):
        code = (
            f"import {module}; from distgprl.sim.bullet import PhysicsConfig, make_client; "
            "make_client(PhysicsConfig()).disconnect(); print('done')"
        )
        result = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
        )
        assert result.returncode == 0, result.stderr
        assert (result.stdout, result.stderr) == ("done\n", ""), module
