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

The subspace is expensive: :func:`build_or_load` caches it as a small ``.npz`` keyed by a hash of
every input (config, obstacles, robot id, joint limits). The static scene is baked in; moving
obstacles are handled by :func:`filter_with_edf`, which drops C_safe points whose clearance under
the current distance field is below a margin instead of rebuilding, and, per replay sample in the
actor loss, by :class:`MovingObstacleFilter`.

Numerics only (numpy/scipy/matplotlib): IK and collision checking are callables supplied by the
caller (e.g. the simulator's robot and a PyBullet checker).
"""

from __future__ import annotations

import hashlib
import heapq
import json
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from dataclasses import field as dataclass_field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from distgprl.safety.edf import DistanceField
from distgprl.safety.shapes import Box, Cylinder, Plane, Shape

__all__ = [
    "ALGORITHM_VERSION",
    "HapBuildStats",
    "HapConfig",
    "SafeSubspace",
    "build_or_load",
    "build_subspace",
    "MovingObstacleFilter",
    "filter_with_edf",
    "plot_subspace",
    "safe_mask",
    "tool_bounds",
    "subspace_cache_key",
]

# Bumped whenever the algorithm changes what it builds (invalidates caches).
ALGORITHM_VERSION = 1

IkFunction = Callable[[np.ndarray], np.ndarray]
CollisionFunction = Callable[[np.ndarray], bool]
ProgressFunction = Callable[[str, int, int], None]

_TWO_PI = 2.0 * np.pi
# Tool pointing down (tool z = -world z): rotation vector (pi, 0, 0), UR convention.
_DOWN = (np.pi, 0.0, 0.0)


def _down_with_yaw(yaw: float) -> tuple[float, float, float]:
    rotation = Rotation.from_euler("z", yaw) * Rotation.from_rotvec(_DOWN)
    return tuple(float(v) for v in rotation.as_rotvec())


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
    return solutions + _TWO_PI * np.round((reference - solutions) / _TWO_PI)


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

    def _report(self, stage: str, done: int, total: int) -> None:
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
                self._report("ik", i + 1, n_poses)
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

    def expand(self, root: int, root_solution: np.ndarray) -> tuple[dict, float]:
        """Step 4: Dijkstra-like expansion from (root pose, IK solution).

        Returns ``mapped`` = {pose: (configuration (6,), cost, parent pose)} and the total cost.
        """
        epsilon = self.config.epsilon
        mapped: dict[int, tuple[np.ndarray, float, int]] = {}
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
    best: tuple[dict, float, int] | None = None
    for k, (root, q) in enumerate(jobs):
        mapped, total = builder.expand(root, q)
        if best is None or total < best[1] - 1e-9:
            best = (mapped, total, root)
        builder._report("expand", k + 1, len(jobs))
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


# ---------------------------------------------------------------------------- cache
def _shape_record(shape: Shape) -> dict:
    def numbers(value: object) -> list:
        return np.round(np.asarray(value, dtype=float), 9).ravel().tolist()

    record: dict = {"kind": type(shape).__name__, "name": shape.name, "dynamic": shape.dynamic}
    record["position"] = numbers(shape.position)
    if isinstance(shape, Plane):
        record["normal"] = numbers(shape.normal)
    elif isinstance(shape, Box):
        record["rotation"] = numbers(shape.rotation)
        record["half_extents"] = numbers(shape.half_extents)
    elif isinstance(shape, Cylinder):
        record["rotation"] = numbers(shape.rotation)
        record["size"] = numbers([shape.radius, shape.half_length])
    return record


def subspace_cache_key(
    config: HapConfig,
    obstacles: Sequence[Shape],
    robot_id: str,
    joint_lower: Sequence[float] | np.ndarray = (-_TWO_PI,) * 6,
    joint_upper: Sequence[float] | np.ndarray = (_TWO_PI,) * 6,
) -> str:
    """SHA-256 (hex) of every build input: config, obstacles, robot id, joint limits, version.

    ``robot_id`` must identify what the callables encode but the hash cannot see: robot model,
    tool and TCP, collision model (e.g. ``"ur5e+shovel/tcp-v1"``).
    """
    payload = {
        "algorithm_version": ALGORITHM_VERSION,
        "config": asdict(config),
        "obstacles": [_shape_record(s) for s in obstacles],
        "robot_id": robot_id,
        "joint_lower": np.round(np.asarray(joint_lower, dtype=float), 9).tolist(),
        "joint_upper": np.round(np.asarray(joint_upper, dtype=float), 9).tolist(),
    }
    text = json.dumps(payload, sort_keys=True, default=float)
    return hashlib.sha256(text.encode()).hexdigest()


def _config_from_json(data: dict) -> HapConfig:
    def tupled(value: object) -> object:
        if isinstance(value, list):
            return tuple(tupled(v) for v in value)
        return value

    return HapConfig(**{k: tupled(v) for k, v in data.items()})


def save_subspace(subspace: SafeSubspace, path: str | Path) -> None:
    """Write the subspace to ``path`` (.npz) atomically (temp file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = json.dumps({"config": asdict(subspace.config), "stats": asdict(subspace.stats)})
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as stream:
            np.savez(
                stream,
                positions=subspace.positions,
                rotations=subspace.rotations,
                configurations=subspace.configurations,
                costs=subspace.costs,
                parents=subspace.parents,
                pose_indices=subspace.pose_indices,
                meta=np.array(meta),
            )
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise


def load_subspace(path: str | Path) -> SafeSubspace:
    """Read a subspace written by :func:`save_subspace`."""
    with np.load(Path(path), allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        return SafeSubspace(
            positions=data["positions"],
            rotations=data["rotations"],
            configurations=data["configurations"],
            costs=data["costs"],
            parents=data["parents"],
            pose_indices=data["pose_indices"],
            config=_config_from_json(meta["config"]),
            stats=HapBuildStats(**meta["stats"]),
        )


def build_or_load(
    config: HapConfig,
    ik_all: IkFunction,
    in_collision: CollisionFunction,
    *,
    obstacles: Sequence[Shape],
    robot_id: str,
    cache_dir: str | Path,
    joint_lower: Sequence[float] | np.ndarray = (-_TWO_PI,) * 6,
    joint_upper: Sequence[float] | np.ndarray = (_TWO_PI,) * 6,
    progress: ProgressFunction | None = None,
) -> tuple[SafeSubspace, bool]:
    """The cached subspace for these inputs, building and caching it on a miss.

    Args:
        config, ik_all, in_collision, joint_lower, joint_upper, progress: as
            :func:`build_subspace`.
        obstacles: the (static) shapes ``in_collision`` checks against; hashed only.
        robot_id: identifies robot, tool/TCP and collision model; hashed only.
        cache_dir: directory of ``hap_<key>.npz`` files.

    Returns:
        (subspace, loaded): ``loaded`` is True on a cache hit.
    """
    key = subspace_cache_key(config, obstacles, robot_id, joint_lower, joint_upper)
    path = Path(cache_dir) / f"hap_{key[:24]}.npz"
    if path.exists():
        return load_subspace(path), True
    subspace = build_subspace(
        config,
        ik_all,
        in_collision,
        joint_lower=joint_lower,
        joint_upper=joint_upper,
        progress=progress,
    )
    subspace = replace(subspace, stats=replace(subspace.stats, cache_key=key))
    save_subspace(subspace, path)
    return subspace, False


# ---------------------------------------------------------------------------- moving obstacles
def safe_mask(
    positions: np.ndarray, field: DistanceField, margin: float, *, dynamic_only: bool = True
) -> np.ndarray:
    """Boolean mask (m,) of ``positions`` (m, 3) whose EDF clearance is at least ``margin`` (m).

    With ``dynamic_only`` only shapes flagged ``dynamic`` count: the static scene is already
    baked into the subspace (and e.g. the table plane is close to every low pose by design).
    """
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    per_shape = field.distance_per_shape(positions)
    if dynamic_only:
        per_shape = per_shape[:, field.dynamic_mask]
    if per_shape.shape[1] == 0:
        return np.ones(len(positions), dtype=bool)
    return per_shape.min(axis=1) >= margin


def filter_with_edf(
    subspace: SafeSubspace | np.ndarray,
    field: DistanceField,
    margin: float,
    *,
    dynamic_only: bool = True,
) -> np.ndarray:
    """C_safe positions (m', 3), m, that keep ``margin`` (m) clearance from the current obstacles.

    The cheap update of C_safe for moving obstacles (DESIGN §4): one EDF query over the (unique)
    subspace positions instead of a rebuild. The margin should cover the tool around the TCP.
    ``subspace`` may be a :class:`SafeSubspace` (its unique positions are used) or an (m, 3)
    array of positions.
    """
    positions = subspace.unique_positions if isinstance(subspace, SafeSubspace) else subspace
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    return positions[safe_mask(positions, field, margin, dynamic_only=dynamic_only)]


class MovingObstacleFilter:
    """Which C_safe points a translating moving obstacle blocks (DESIGN §4, per sample).

    :func:`filter_with_edf` filters C_safe once for the obstacles' current poses; the actor loss
    needs the filter per replay sample, each with the obstacles elsewhere. The moving obstacles
    of both tasks only translate, so they are described once by a *template* (their boxes with
    the anchor, the first box's centre, at the origin) and per sample by the anchor position.

    A C_safe position p (a TCP position) is blocked when the tool held at p would come within
    ``margin`` of a moving box. The tool is bounded by an axis-aligned box around the TCP
    (``tool_offset`` centre, ``tool_half_extents``; e.g. :func:`tool_bounds` over the
    demonstration's orientations), so the test is an EDF query of the template with every box
    grown by the tool's extent (Minkowski sum; for a rotated box the tool box's extent along
    the box axes, which is conservative): clearance(p - anchor - tool_offset) < margin.

    Args:
        shapes: the moving obstacles at some instant; boxes only (the tasks' obstacles).
        tool_offset: centre of the tool's bounding box relative to the TCP, shape (3,), m.
        tool_half_extents: its half extents, shape (3,), m (zeros: the TCP point only).
        margin: required clearance, m (e.g. d_min of Eq. safety_reward).
    """

    def __init__(
        self,
        shapes: Sequence[Shape],
        tool_offset: np.ndarray,
        tool_half_extents: np.ndarray,
        margin: float,
    ) -> None:
        if not shapes:
            raise ValueError("a moving-obstacle filter needs at least one moving shape")
        if margin <= 0:
            raise ValueError(f"margin must be positive, got {margin}")
        offset = np.asarray(tool_offset, dtype=float).reshape(3)
        grow = np.asarray(tool_half_extents, dtype=float).reshape(3)
        if np.any(grow < 0):
            raise ValueError("tool_half_extents must be non-negative")
        anchor = np.asarray(shapes[0].position, dtype=float)
        template = []
        for shape in shapes:
            if not isinstance(shape, Box):
                raise TypeError(f"moving obstacle {shape.name!r}: only boxes are supported")
            rotation = np.asarray(shape.rotation, dtype=float)
            template.append(
                replace(
                    shape,
                    position=np.asarray(shape.position, dtype=float) - anchor - offset,
                    rotation=rotation,
                    half_extents=np.asarray(shape.half_extents, dtype=float)
                    + np.abs(rotation.T) @ grow,
                )
            )
        self.template = tuple(template)
        self.margin = float(margin)
        self._centres = np.stack([b.position for b in template])
        self._rotations = np.stack([b.rotation for b in template])
        self._half_extents = np.stack([b.half_extents for b in template])
        self._axis_aligned = bool(np.allclose(self._rotations, np.eye(3)))
        lower = (self._centres - self._half_extents).min(axis=0) - self.margin
        upper = (self._centres + self._half_extents).max(axis=0) + self.margin
        self._middle, self._span = (lower + upper) / 2.0, (upper - lower) / 2.0
        # Points further than this from the anchor cannot be blocked (a cheap first cut).
        self.reach = (
            max(
                float(np.linalg.norm(b.position) + np.linalg.norm(b.half_extents)) for b in template
            )
            + self.margin
        )

    @staticmethod
    def anchor(shapes: Sequence[Shape]) -> np.ndarray:
        """The anchor position (3,), m, of moving obstacles given as ``shapes``."""
        return np.asarray(shapes[0].position, dtype=float).copy()

    def blocked(self, points: np.ndarray, anchors: np.ndarray) -> np.ndarray:
        """Boolean mask, shape ``points.shape[:-1]``: the point is blocked.

        Equal to ``DistanceField(template).clearance(points - anchor) < margin``, computed
        directly for boxes: outside a box its distance is |max(|R^T (p - c)| - h, 0)|.

        Args:
            points: C_safe positions, shape (..., c, 3), m.
            anchors: the obstacles' anchor per row, shape (..., 3), m.
        """
        points = np.asarray(points, dtype=float)
        anchors = np.asarray(anchors, dtype=float)
        if self._axis_aligned:
            return self._blocked_axis_aligned(points, anchors)
        relative = (points - anchors[..., None, :]).reshape(-1, 3)
        out = np.zeros(len(relative), dtype=bool)
        near = np.flatnonzero(np.einsum("ij,ij->i", relative, relative) < self.reach**2)
        if near.size:
            local = relative[near][:, None, :] - self._centres  # (m, boxes, 3)
            local = np.einsum("mbi,bij->mbj", local, self._rotations)
            local = np.abs(local, out=local) - self._half_extents
            np.maximum(local, 0.0, out=local)
            squared = np.einsum("mbi,mbi->mb", local, local)
            out[near] = (squared < self.margin**2).any(axis=1)
        return out.reshape(points.shape[:-1])

    def _blocked_axis_aligned(self, points: np.ndarray, anchors: np.ndarray) -> np.ndarray:
        """`blocked` for axis-aligned boxes, one coordinate array at a time (no (m, 3) rows):
        points inside the boxes' common bounding box (grown by the margin), then per box
        |max(|p - a - c| - h, 0)|^2 < margin^2, summed over the axes in x, y, z order."""
        relative = [points[..., i] - anchors[..., None, i] for i in range(3)]  # (..., c) each
        inside = np.abs(relative[0] - self._middle[0]) < self._span[0]
        for i in (1, 2):
            inside &= np.abs(relative[i] - self._middle[i]) < self._span[i]
        out = np.zeros(inside.shape, dtype=bool)
        near = np.flatnonzero(inside)
        if near.size:
            local = [r.reshape(-1)[near] for r in relative]
            hit = np.zeros(near.size, dtype=bool)
            for centre, half in zip(self._centres, self._half_extents, strict=True):
                squared = None
                for i in range(3):
                    excess = np.abs(local[i] - centre[i])
                    excess -= half[i]
                    np.maximum(excess, 0.0, out=excess)
                    excess *= excess
                    squared = excess if squared is None else squared + excess
                hit |= squared < self.margin**2
            out.reshape(-1)[near] = hit
        return out


def tool_bounds(tool_points: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box (centre, half extents), each (3,), m, around the TCP containing the tool.

    Args:
        tool_points: tool points in the TCP frame, shape (m, 3), m.
        rotations: world-from-TCP rotations the box must cover, shape (r, 3, 3).
    """
    world = np.einsum("rij,mj->rmi", np.asarray(rotations, dtype=float), tool_points)
    lower = world.reshape(-1, 3).min(axis=0)
    upper = world.reshape(-1, 3).max(axis=0)
    return (lower + upper) / 2.0, (upper - lower) / 2.0


# ---------------------------------------------------------------------------- figure
def _draw_shape(axes, shape: Shape, extent: np.ndarray) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    colour = "tab:red" if shape.dynamic else "dimgray"
    if isinstance(shape, Box):
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        corners = shape.position + (signs * shape.half_extents) @ np.asarray(shape.rotation).T
        faces = [
            [0, 1, 3, 2],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 3, 7, 5],
        ]
        axes.add_collection3d(
            Poly3DCollection(
                [corners[f] for f in faces], facecolor=colour, alpha=0.25, edgecolor=colour
            )
        )
    elif isinstance(shape, Cylinder):
        angle = np.linspace(0, 2 * np.pi, 25)
        circle = np.stack((np.cos(angle), np.sin(angle), np.zeros_like(angle)), axis=1)
        rotation = np.asarray(shape.rotation)
        for z in (-shape.half_length, shape.half_length):
            ring = shape.position + (circle * shape.radius + [0, 0, z]) @ rotation.T
            axes.plot(*ring.T, color=colour, linewidth=1)
        for k in range(0, 24, 3):
            ends = np.array([[0, 0, -shape.half_length], [0, 0, shape.half_length]])
            ends[:, :2] = circle[k, :2] * shape.radius
            line = shape.position + ends @ rotation.T
            axes.plot(*line.T, color=colour, linewidth=1)
    elif isinstance(shape, Plane):
        normal = np.asarray(shape.normal, dtype=float) / np.linalg.norm(shape.normal)
        from distgprl.safety.edf import frame_from_normal

        frame = frame_from_normal(normal)
        half = 0.5 * np.max(extent[1] - extent[0]) + 0.1
        centre = np.asarray(shape.position, dtype=float)
        # Centre the patch under the plotted region (projected onto the plane).
        middle = extent.mean(axis=0)
        centre = middle - normal * (normal @ (middle - centre))
        square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
        corners = centre + square @ frame[:, :2].T
        axes.add_collection3d(
            Poly3DCollection([corners], facecolor="tan", alpha=0.2, edgecolor="none")
        )


def plot_subspace(
    subspace: SafeSubspace,
    shapes: Sequence[Shape],
    out_path: str | Path,
    *,
    title: str | None = None,
) -> Path:
    """Write a 3-D scatter PNG of C_safe (coloured by joint path cost) with the obstacles.

    Args:
        subspace: the subspace to draw.
        shapes: obstacle shapes to draw (static grey, dynamic red).
        out_path: PNG path (parent directories are created).
        title: figure title (default: size and build statistics).

    Returns:
        The written path.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    figure = Figure(figsize=(7, 6), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(projection="3d")
    config = subspace.config
    extent = np.array([config.workspace_lower, config.workspace_upper], dtype=float)
    if len(subspace):
        points = axes.scatter(
            *subspace.positions.T, c=subspace.costs, cmap="viridis", s=14, depthshade=False
        )
        figure.colorbar(
            points, ax=axes, shrink=0.6, pad=0.12, label="joint path cost from root (rad)"
        )
        root = subspace.positions[subspace.parents < 0]
        axes.scatter(*root.T, marker="*", s=120, color="tab:orange", label="root")
        axes.legend(loc="upper left")
    for shape in shapes:
        _draw_shape(axes, shape, extent)
    pad = 0.1
    bottom = min(extent[0, 2] - pad, 0.0)
    for shape in shapes:  # show horizontal planes (the table) below the grid
        if isinstance(shape, Plane) and abs(shape.normal[2]) > 0.9 * np.linalg.norm(shape.normal):
            bottom = min(bottom, float(shape.position[2]))
    limits = np.array(
        [
            [extent[0, 0] - pad, extent[1, 0] + pad],
            [extent[0, 1] - pad, extent[1, 1] + pad],
            [bottom, extent[1, 2] + pad],
        ]
    )
    axes.set_xlim(*limits[0])
    axes.set_ylim(*limits[1])
    axes.set_zlim(*limits[2])
    axes.set_box_aspect(limits[:, 1] - limits[:, 0])
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_zlabel("z (m)")
    stats = subspace.stats
    axes.set_title(
        title
        or f"HAP C_safe: {stats.n_mapped} mapped of {stats.n_reachable} reachable poses "
        f"({len(subspace.unique_positions)} positions)"
    )
    figure.savefig(out_path)
    return out_path
