"""PyBullet simulation of the tasks (scenes, robot, experts, rendering).

pybullet is imported here first, with its start-up banner kept off stdout
(`distgprl.sim.quiet`), so that no module of this package prints it whichever is imported
first.
"""

from distgprl.sim.quiet import stdout_to_devnull

with stdout_to_devnull():
    import pybullet  # noqa: F401
