"""HAP safe subspace C_safe (paper §IV-B; Sukkar et al., T-RO 2025; DESIGN §4).

The Hausdorff Approximation Planner's traversable subspace, built with the published algorithm:

1. Discretise task-space poses: a position grid over a workspace box (``grid_step``, m) times a
   few tool orientations.
2. For every pose, all analytic IK solutions (``ik_all``), keeping the collision-free ones
   (``in_collision``). Poses without one are unreachable.
3. Pose graph: two reachable poses are neighbours if their positions are at most
   ``neighbour_radius`` apart (0.16 m: the 18-neighbourhood of a 0.1 m grid) and their tool
   orientations at most ``orientation_radius`` apart.
4. From a root pose and each of its IK solutions, a Dijkstra-like expansion over the pose graph:
   from the current pose's configuration q, every neighbour takes an IK solution within
   ``epsilon`` (L-infinity, rad) of q, whose joint-space segment from q is collision-free
   (``edge_checks`` interpolated configurations), at cost ``+ ||Δq||_2`` (joint-space path
   length). A pose is mapped with the cheapest such configuration that is also within
   ``epsilon`` of every already-mapped neighbour, so the mapped configurations form one
   continuous branch: *all* neighbouring mapped poses differ by at most ``epsilon`` (L∞).
5. The expansion's cost is the sum of the mapped poses' path costs plus ``c_max`` per
   reachable but unmapped pose; over the root candidates (the ``root_candidates`` reachable
   poses nearest ``root_position`` or the grid centre, each with all its IK solutions) the
   cheapest expansion is kept. Its mapped positions are C_safe.

Joint wrap-around: IK solvers return principal joint values; a neighbour's solution is shifted
per joint by multiples of 2 pi to be nearest the current configuration (within the joint
limits) before the epsilon test, so a branch can cross ±pi. ``in_collision`` must therefore be a
function of the geometry only (2 pi-periodic per joint), as any FK-based checker is.

The subspace is expensive: :func:`~distgprl.safety.hap_cache.build_or_load` caches it as a
small ``.npz`` keyed by a hash of every input (config, obstacles, robot id, joint limits). The
static scene is baked in; moving obstacles are handled by
:func:`~distgprl.safety.hap_filter.filter_with_edf`, which drops C_safe points whose clearance
under the current distance field is below a margin instead of rebuilding, and, per replay
sample in the actor loss, by :class:`~distgprl.safety.hap_filter.MovingObstacleFilter`.

Numerics only (numpy/scipy; tqdm for the optional progress bars): IK and collision checking
are callables supplied by the caller (e.g. the simulator's robot and a PyBullet checker).
"""

from __future__ import annotations

import heapq
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import TYPE_CHECKING, Any, NoReturn, TextIO

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

if TYPE_CHECKING:
    from tqdm import tqdm

__all__ = [
    "ALGORITHM_VERSION",
    "CollisionFunction",
    "HapBuildStats",
    "HapConfig",
    "IkFunction",
    "ProgressFunction",
    "SafeSubspace",
    "build_subspace",
    "tqdm_progress",
]

# Bumped whenever the algorithm changes what it builds (invalidates caches).
ALGORITHM_VERSION = 1

IkFunction = Callable[[np.ndarray], np.ndarray]
CollisionFunction = Callable[[np.ndarray], bool]
ProgressFunction = Callable[[str, int, int], None]
#: A root's expansion (`_Builder.expand`): pose index -> (configuration (6,), joint path cost
#: from the root, parent pose index or -1).
Mapped = dict[int, tuple[np.ndarray, float, int]]

_TWO_PI = 2.0 * np.pi
# Tool pointing down (tool z = -world z): rotation vector (pi, 0, 0), UR convention.
_DOWN = (np.pi, 0.0, 0.0)


def _down_with_yaw(yaw: float) -> tuple[float, float, float]:
    rotation = Rotation.from_euler("z", yaw) * Rotation.from_rotvec(_DOWN)
    x, y, z = rotation.as_rotvec()
    return (float(x), float(y), float(z))


@dataclass(frozen=True)
class HapConfig:
    """Inputs of the HAP subspace build (DESIGN §4 defaults).

    Attributes:
        workspace_lower, workspace_upper: corners of the position grid box, robot base frame, m.
        grid_step: grid spacing, m (0.1 m).
        orientations: tool orientations as rotation vectors (UR convention), rad. Default: tool
            pointing down with yaw -45°, 0°, +45° (adjacent ones are 0.785 rad apart).
        neighbour_radius: poses whose positions are at most this far apart are neighbours, m
            (0.16 m: face and edge neighbours of a 0.1 m grid).
        orientation_radius: ... and whose orientations are at most this far apart, rad.
        epsilon: max joint change (L∞) between neighbouring mapped configurations, rad (1 rad).
        edge_checks: interpolated configurations collision-checked on each expansion edge.
        c_max: cost of a reachable pose that an expansion does not map, rad (larger than any
            path cost, so coverage dominates path length).
        root_candidates: number of root poses tried (each with all its IK solutions).
        root_position: roots are the reachable poses nearest this point (m); None = grid centre.
    """

    workspace_lower: tuple[float, float, float] = (0.2, -0.5, 0.05)
    workspace_upper: tuple[float, float, float] = (0.8, 0.5, 0.6)
    grid_step: float = 0.1
    orientations: tuple[tuple[float, float, float], ...] = (
        _down_with_yaw(-np.pi / 4),
        _DOWN,
        _down_with_yaw(np.pi / 4),
    )
    neighbour_radius: float = 0.16
    orientation_radius: float = 0.8
    epsilon: float = 1.0
    edge_checks: int = 4
    c_max: float = 1000.0
    root_candidates: int = 3
    root_position: tuple[float, float, float] | None = None

    def grid_positions(self) -> np.ndarray:
        """Grid positions, shape (p, 3), m (lexicographic in x, y, z; z varies fastest)."""
        axes = [
            np.arange(lo, hi + 0.5 * self.grid_step, self.grid_step)
            for lo, hi in zip(self.workspace_lower, self.workspace_upper, strict=True)
        ]
        mesh = np.meshgrid(*axes, indexing="ij")
        return np.stack([m.ravel() for m in mesh], axis=1)

    def rotation_matrices(self) -> np.ndarray:
        """Tool orientations as rotation matrices, shape (o, 3, 3)."""
        return Rotation.from_rotvec(np.asarray(self.orientations, dtype=float)).as_matrix()


@dataclass(frozen=True)
class HapBuildStats:
    """What the build did (reported by the CLI, stored in the cache)."""

    n_poses: int  # grid positions x orientations
    n_reachable: int  # poses with at least one collision-free IK solution
    n_mapped: int  # poses in the chosen expansion (= len(C_safe) with orientations)
    n_expansions: int  # root (pose, IK solution) pairs tried
    root_pose: int  # index of the chosen root in the pose grid
    total_cost: float  # sum of path costs + c_max per unmapped reachable pose, rad
    ik_calls: int
    collision_checks: int
    build_seconds: float
    cache_key: str = ""


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class SafeSubspace:
    """The HAP safe subspace: mapped poses and their joint configurations (one branch).

    Attributes:
        positions: C_safe, mapped tool positions, shape (m, 3), m (a position appears once per
            mapped orientation; see :attr:`unique_positions`).
        rotations: mapped tool orientations, shape (m, 3, 3).
        configurations: mapped joint configurations, shape (m, 6), rad (IK of the pose,
            collision-free, wrapped to the branch).
        costs: joint-space path length from the root, shape (m,), rad.
        parents: index (into these arrays) of the pose each one was reached from, (m,); -1 for
            the root.
        pose_indices: index of each mapped pose in the build grid (position * o + orientation),
            shape (m,).
        edges: expansion tree edges (parent, child), shape (m - 1, 2), collision-checked.
        config: the build configuration.
        stats: build statistics.
    """

    positions: np.ndarray
    rotations: np.ndarray
    configurations: np.ndarray
    costs: np.ndarray
    parents: np.ndarray
    pose_indices: np.ndarray
    config: HapConfig
    stats: HapBuildStats
    edges: np.ndarray = dataclass_field(init=False)

    def __post_init__(self) -> None:
        for name in ("positions", "rotations", "configurations", "costs", "parents"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        object.__setattr__(self, "pose_indices", _readonly(self.pose_indices))
        child = np.flatnonzero(self.parents >= 0)
        object.__setattr__(
            self, "edges", _readonly(np.stack((self.parents[child], child), axis=1).reshape(-1, 2))
        )

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def unique_positions(self) -> np.ndarray:
        """C_safe without repeated positions (several orientations), shape (m', 3), m."""
        return np.unique(np.round(self.positions, 9), axis=0)


# ---------------------------------------------------------------------------- build
def _wrap_towards(solutions: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Shift each joint of ``solutions`` (k, 6) by multiples of 2 pi nearest ``reference``."""
    wrapped: np.ndarray = solutions + _TWO_PI * np.round((reference - solutions) / _TWO_PI)
    return wrapped


class _Builder:
    """State of one build: per-pose IK solutions, pose graph, collision caches."""

    def __init__(
        self,
        config: HapConfig,
        ik_all: IkFunction,
        in_collision: CollisionFunction,
        joint_lower: np.ndarray,
        joint_upper: np.ndarray,
        progress: ProgressFunction | None,
    ) -> None:
        self.config = config
        self.ik_all = ik_all
        self.in_collision = in_collision
        self.lower = joint_lower
        self.upper = joint_upper
        self.progress = progress
        self.collision_checks = 0
        self.ik_calls = 0
        self._edge_cache: dict[bytes, bool] = {}

    def report_progress(self, stage: str, done: int, total: int) -> None:
        """Pass ``done`` of ``total`` items of ``stage`` to the progress callback, if any."""
        if self.progress is not None:
            self.progress(stage, done, total)

    def _collides(self, q: np.ndarray) -> bool:
        self.collision_checks += 1
        return bool(self.in_collision(q))

    def solve_poses(self) -> None:
        """Steps 1-2: the pose grid and the collision-free IK solutions of every pose."""
        positions = self.config.grid_positions()
        rotations = self.config.rotation_matrices()
        n_orient = len(rotations)
        self.pose_positions = np.repeat(positions, n_orient, axis=0)
        self.pose_rotations = np.tile(rotations, (len(positions), 1, 1))
        self.pose_orientation = np.tile(np.arange(n_orient), len(positions))
        n_poses = len(self.pose_positions)
        self.solutions: list[np.ndarray] = []
        for i in range(n_poses):
            transform = np.eye(4)
            transform[:3, :3] = self.pose_rotations[i]
            transform[:3, 3] = self.pose_positions[i]
            self.ik_calls += 1
            raw = np.asarray(self.ik_all(transform), dtype=float).reshape(-1, 6)
            raw = raw[np.all(np.isfinite(raw), axis=1)]
            keep = [q for q in raw if not self._collides(q)]
            self.solutions.append(np.asarray(keep).reshape(-1, 6))
            if i % 50 == 0 or i == n_poses - 1:
                self.report_progress("ik", i + 1, n_poses)
        self.reachable = np.flatnonzero([len(s) > 0 for s in self.solutions])

    def build_graph(self) -> None:
        """Step 3: neighbours among reachable poses (position and orientation radius)."""
        config = self.config
        rotations = self.config.rotation_matrices()
        # Geodesic angle between orientation pairs: acos((trace(Ra^T Rb) - 1) / 2).
        traces = np.einsum("aij,bij->ab", rotations, rotations)
        angles = np.arccos(np.clip((traces - 1.0) / 2.0, -1.0, 1.0))
        orientation_ok = angles <= config.orientation_radius + 1e-9
        reachable = self.reachable
        tree = cKDTree(self.pose_positions[reachable])
        pairs = tree.query_pairs(config.neighbour_radius + 1e-9, output_type="ndarray")
        # Pairs include same-position poses (other orientation, distance 0).
        a, b = reachable[pairs[:, 0]], reachable[pairs[:, 1]]
        keep = orientation_ok[self.pose_orientation[a], self.pose_orientation[b]]
        self.neighbours: dict[int, list[int]] = {int(i): [] for i in reachable}
        for u, v in zip(a[keep], b[keep], strict=True):
            self.neighbours[int(u)].append(int(v))
            self.neighbours[int(v)].append(int(u))

    def _edge_free(self, q_from: np.ndarray, q_to: np.ndarray) -> bool:
        """Joint interpolation of the edge is collision-free (endpoints already are)."""
        key = np.round(np.concatenate((q_from, q_to)), 9).tobytes()
        cached = self._edge_cache.get(key)
        if cached is not None:
            return cached
        steps = self.config.edge_checks
        free = True
        for t in np.arange(1, steps + 1) / (steps + 1):
            if self._collides(q_from + t * (q_to - q_from)):
                free = False
                break
        self._edge_cache[key] = free
        return free

    def expand(self, root: int, root_solution: np.ndarray) -> tuple[Mapped, float]:
        """Step 4: Dijkstra-like expansion from (root pose, IK solution).

        Returns ``mapped`` = {pose: (configuration (6,), cost, parent pose)} and the total cost.
        """
        epsilon = self.config.epsilon
        mapped: Mapped = {}
        counter = 0
        heap: list[tuple[float, int, int, np.ndarray, int]] = [(0.0, 0, root, root_solution, -1)]
        while heap:
            cost, _, pose, q, parent = heapq.heappop(heap)
            if pose in mapped:
                continue
            # One continuous branch: within epsilon of every mapped neighbour, not just the parent.
            consistent = True
            for other in self.neighbours[pose]:
                if other in mapped and np.max(np.abs(mapped[other][0] - q)) > epsilon:
                    consistent = False
                    break
            if not consistent:
                continue
            if parent >= 0 and not self._edge_free(mapped[parent][0], q):
                continue
            mapped[pose] = (q, cost, parent)
            for other in self.neighbours[pose]:
                if other in mapped:
                    continue
                candidates = _wrap_towards(self.solutions[other], q)
                step = candidates - q
                ok = np.max(np.abs(step), axis=1) <= epsilon
                ok &= np.all((candidates >= self.lower) & (candidates <= self.upper), axis=1)
                for index in np.flatnonzero(ok):
                    counter += 1
                    # Cost: joint-space path length.
                    length = float(np.linalg.norm(step[index]))
                    heapq.heappush(heap, (cost + length, counter, other, candidates[index], pose))
        path_costs = sum(entry[1] for entry in mapped.values())
        unmapped = len(self.reachable) - len(mapped)
        return mapped, path_costs + self.config.c_max * unmapped

    def root_candidates(self) -> np.ndarray:
        """Step 5: the reachable poses nearest the root position (or the grid centre)."""
        config = self.config
        if config.root_position is None:
            target = 0.5 * (np.asarray(config.workspace_lower) + np.asarray(config.workspace_upper))
        else:
            target = np.asarray(config.root_position, dtype=float)
        distance = np.linalg.norm(self.pose_positions[self.reachable] - target, axis=1)
        # Prefer well-connected poses among equally near ones (stable order for ties).
        degree = np.array([len(self.neighbours[int(i)]) for i in self.reachable])
        order = np.lexsort((-degree, np.round(distance, 9)))
        return self.reachable[order[: config.root_candidates]]


def build_subspace(
    config: HapConfig,
    ik_all: IkFunction,
    in_collision: CollisionFunction,
    *,
    joint_lower: Sequence[float] | np.ndarray = (-_TWO_PI,) * 6,
    joint_upper: Sequence[float] | np.ndarray = (_TWO_PI,) * 6,
    progress: ProgressFunction | None = None,
) -> SafeSubspace:
    """Build the HAP safe subspace (module docstring, steps 1-5).

    Args:
        config: grid, orientations and algorithm parameters.
        ik_all: ``T (4, 4) -> (k, 6)`` all IK solutions (rad) reaching the tool pose ``T``
            (robot base frame, m); ``k = 0`` if unreachable.
        in_collision: ``q (6,) -> bool``, True if configuration ``q`` collides with the static
            scene (or itself). Must depend on the geometry only (2 pi-periodic per joint).
        joint_lower, joint_upper: joint limits (6,), rad, for wrapped configurations.
        progress: optional ``callback(stage, done, total)``; stages ``"ik"`` and ``"expand"``.

    Returns:
        The subspace of the cheapest expansion (empty if no pose is reachable).
    """
    start = time.perf_counter()
    builder = _Builder(
        config,
        ik_all,
        in_collision,
        np.asarray(joint_lower, dtype=float),
        np.asarray(joint_upper, dtype=float),
        progress,
    )
    builder.solve_poses()
    builder.build_graph()
    roots = builder.root_candidates() if len(builder.reachable) else np.zeros(0, dtype=int)
    jobs = [(int(root), q) for root in roots for q in builder.solutions[root]]
    best: tuple[Mapped, float, int] | None = None
    for k, (root, q) in enumerate(jobs):
        mapped, total = builder.expand(root, q)
        if best is None or total < best[1] - 1e-9:
            best = (mapped, total, root)
        builder.report_progress("expand", k + 1, len(jobs))
    mapped, total, root = best if best is not None else ({}, 0.0, -1)
    # Arrays in pose-grid order; parents re-indexed into the mapped arrays.
    poses = np.array(sorted(mapped), dtype=int)
    position_of = {int(p): i for i, p in enumerate(poses)}
    stats = HapBuildStats(
        n_poses=len(builder.pose_positions),
        n_reachable=len(builder.reachable),
        n_mapped=len(poses),
        n_expansions=len(jobs),
        root_pose=int(root),
        total_cost=float(total),
        ik_calls=builder.ik_calls,
        collision_checks=builder.collision_checks,
        build_seconds=time.perf_counter() - start,
    )
    return SafeSubspace(
        positions=builder.pose_positions[poses].reshape(-1, 3),
        rotations=builder.pose_rotations[poses].reshape(-1, 3, 3),
        configurations=np.array([mapped[int(p)][0] for p in poses]).reshape(-1, 6),
        costs=np.array([mapped[int(p)][1] for p in poses], dtype=float),
        parents=np.array(
            [position_of.get(mapped[int(p)][2], -1) for p in poses], dtype=int
        ).reshape(-1),
        pose_indices=poses,
        config=config,
        stats=stats,
    )


def tqdm_progress(file: TextIO | None = None, **options: Any) -> ProgressFunction:
    """A :data:`ProgressFunction` drawing one tqdm bar per build stage (``ik``: poses solved,
    ``expand``: root expansions) on ``file`` (default stderr).

    A bar is created at its stage's first report (so none on a cache hit) and closed at its
    last; as tqdm does by default (``disable=None``), nothing is drawn when the stream is not
    a terminal. ``options`` are passed on to ``tqdm`` (e.g. ``leave=True``).
    """

    bars: dict[str, tqdm[NoReturn]] = {}

    def report(stage: str, done: int, total: int) -> None:
        from tqdm import tqdm

        bar = bars.get(stage)
        if bar is None:
            bar = bars[stage] = tqdm(
                total=total,
                desc=f"HAP {stage}",
                unit="pose" if stage == "ik" else "expansion",
                file=file if file is not None else sys.stderr,
                **{"disable": None, "leave": False, **options},
            )
        bar.update(done - bar.n)
        if done >= total:
            bar.close()

    return report
