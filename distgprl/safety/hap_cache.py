"""HAP subspace cache: the key of every build input, the ``.npz`` file and build-or-load.

A subspace is stored as ``<cache_dir>/hap_<key[:24]>.npz`` (written atomically), ``key`` the
SHA-256 of the config, the static obstacles, the robot id, the joint limits and
:data:`~distgprl.safety.hap_build.ALGORITHM_VERSION` (:func:`subspace_cache_key`), so any
change to an input builds a new file instead of reusing a stale one.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.io import atomic_open, sha256_hex
from distgprl.safety.hap_build import (
    ALGORITHM_VERSION,
    CollisionFunction,
    HapBuildStats,
    HapConfig,
    IkFunction,
    ProgressFunction,
    SafeSubspace,
    build_subspace,
)
from distgprl.safety.shapes import Box, Cylinder, Plane, Shape

__all__ = ["build_or_load", "load_subspace", "save_subspace", "subspace_cache_key"]

_TWO_PI = 2.0 * np.pi


def _shape_record(shape: Shape) -> dict[str, Any]:
    def numbers(value: object) -> list[float]:
        rounded: list[float] = np.round(np.asarray(value, dtype=float), 9).ravel().tolist()
        return rounded

    record: dict[str, Any] = {
        "kind": type(shape).__name__,
        "name": shape.name,
        "dynamic": shape.dynamic,
    }
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
    return sha256_hex(text)


def _config_from_json(data: dict[str, Any]) -> HapConfig:
    def tupled(value: Any) -> Any:  # a JSON value; its lists as tuples
        if isinstance(value, list):
            return tuple(tupled(v) for v in value)
        return value

    return HapConfig(**{k: tupled(v) for k, v in data.items()})


def save_subspace(subspace: SafeSubspace, path: str | Path) -> None:
    """Write the subspace to ``path`` (.npz) atomically (temp file + rename)."""
    meta = json.dumps({"config": asdict(subspace.config), "stats": asdict(subspace.stats)})
    with atomic_open(path) as stream:
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
