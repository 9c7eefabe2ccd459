"""Robots of the task simulations: the `Robot` protocol, tools, and the UR5e (its one
implementation: official kinematics, real joint limits, a rigidly attached tool).

A task simulation (`distgprl.sim.tasks.base.TaskSim`) is given a `RobotFactory` (default
`UR5e`) and calls only what `Robot` declares; the control loop (`distgprl.sim.control`)
likewise. A new robot is one module implementing `Robot` (docs/guides/extending.md "A new robot").

Frames:
- **world** = the UR controller's ``base`` frame (the frame ``ur_rtde`` reports poses
  in and the frame of the demonstration CSVs). The URDF's REP-103 ``base_link`` is
  rotated by pi about z so that the URDF ``base`` link coincides with the world frame.
- **tool0**: the UR flange frame (z out of the flange), as in the official DH model.
- **TCP**: the tool's working point. Its frame is tool0 turned by pi about x, so z
  points back up the tool shaft and y is the tool's working direction (the shovel's
  pushing normal, the hook finger's direction). With the tool pointing straight down
  and working along world +y, the TCP frame equals the world frame (rotation vector
  0), far from the rotation-vector singularity at pi.

Kinematics come from ``ur_analytic_ik`` (official UR5e DH parameters); the PyBullet
model is the URDF that ``airo-models`` ships. The tool is added to that URDF as an
extra link (boxes only) fixed to ``tool0``, so it is part of the same multibody and
perfectly rigid.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Protocol, runtime_checkable

import airo_models
import numpy as np
import pybullet
import ur_analytic_ik
from pybullet_utils.bullet_client import BulletClient

from distgprl.io import atomic_write_text, sha256_hex
from distgprl.sim.ik_branches import nearest_branch
from distgprl.sim.transforms import (
    invert_transform,
    make_transform,
    matrix_to_pose,
    quaternion_to_matrix,
    rotation_x,
    rotation_z,
)
from distgprl.sim.ur_ik import segment_ik

JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
"""The six actuated joints, in controller order."""

_inverse_kinematics = ur_analytic_ik.ur5e.inverse_kinematics


@dataclass(frozen=True)
class ToolBox:
    """One box of a tool's geometry, in the tool0 frame.

    Attributes:
        half_extents: shape (3,), m.
        position: box centre in tool0, shape (3,), m.
    """

    half_extents: tuple[float, float, float]
    position: tuple[float, float, float]


@dataclass(frozen=True)
class ToolSpec:
    """A rigid tool made of boxes, mounted on the flange (tool0 frame).

    Attributes:
        name: tool name (used for the generated URDF).
        boxes: the collision (and visual) boxes, in tool0.
        tcp_position: the working point in tool0, shape (3,), m. The TCP frame is tool0
            rotated by pi about x (see the module docstring).
        mass: kg.
        rgba: display colour.
        surface_points_per_box: how many surface points each box contributes to
            :meth:`UR5e.tool_points` (about 50 in total).
    """

    name: str
    boxes: tuple[ToolBox, ...]
    tcp_position: tuple[float, float, float]
    mass: float = 0.4
    rgba: tuple[float, float, float, float] = (0.55, 0.55, 0.6, 1.0)
    surface_points_per_box: tuple[int, ...] = field(default_factory=tuple)

    @property
    def tool0_from_tcp(self) -> np.ndarray:
        """Transform (4, 4) of the TCP frame in tool0."""
        return make_transform(rotation_x(math.pi), self.tcp_position)


SHOVEL = ToolSpec(
    name="shovel",
    boxes=(
        # shaft, behind the blade, from the flange down to the blade top
        ToolBox(half_extents=(0.0125, 0.0125, 0.09), position=(0.0, 0.0125, 0.09)),
        # blade: 14 cm wide, 6 cm tall, 8 mm thick; its -y face (tool0) pushes
        ToolBox(half_extents=(0.07, 0.004, 0.03), position=(0.0, 0.0, 0.21)),
    ),
    # bottom edge centre of the pushing face
    tcp_position=(0.0, -0.004, 0.24),
    mass=0.5,
    surface_points_per_box=(14, 36),
)
"""DCP tool: a flat shovel blade on a shaft; the TCP is the blade's lower pushing edge."""

HOOK = ToolSpec(
    name="hook",
    boxes=(
        # shank from the flange down
        ToolBox(half_extents=(0.01, 0.01, 0.09), position=(0.0, 0.0, 0.09)),
        # finger at the shank's end, pointing along -y of tool0 (= TCP +y)
        ToolBox(half_extents=(0.01, 0.045, 0.006), position=(0.0, -0.035, 0.174)),
    ),
    # on the finger's upper face, 4 cm in front of the shank
    tcp_position=(0.0, -0.05, 0.168),
    mass=0.4,
    surface_points_per_box=(20, 30),
)
"""DBM tool: an L-shaped hook; the TCP is on the finger's upper face, where a handle rests."""


@runtime_checkable
class Robot(Protocol):
    """What a task simulation and its control loop need of a robot arm with a tool.

    Joint vectors are (n_joints,) in rad (six for the UR5e); transforms are (4, 4) in the
    world frame (the robot's base frame); poses are (6,): x, y, z (m) and a rotation
    vector (rad). The TCP is the tool's working point (`ToolSpec.tcp_position`).

    Attributes:
        name: the robot's identity in cache keys (e.g. the HAP subspace's, ``"ur5e"``).
        tool: the mounted tool.
        body: PyBullet body id (the contact and clearance queries' ``bodyA``).
        lower_limits, upper_limits: joint limits (n_joints,), rad.
    """

    name: str
    tool: ToolSpec
    body: int
    lower_limits: np.ndarray
    upper_limits: np.ndarray

    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP transform (4, 4) for joint positions ``q``."""
        ...

    def ik_all(self, tcp_transform: np.ndarray) -> np.ndarray:
        """Every IK branch (k, n_joints) within the joint limits reaching the TCP transform."""
        ...

    def ik_nearest(
        self, tcp_transform: np.ndarray, q_reference: Sequence[float] | np.ndarray
    ) -> np.ndarray | None:
        """The IK solution nearest ``q_reference`` (n_joints,), or None if unreachable."""
        ...

    def ik_segment(
        self, poses: np.ndarray, q_reference: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Joint targets (n, n_joints) of TCP poses (n, 6), each `ik_nearest` the previous
        target (``q_reference`` for the first; the previous one held where a pose is
        unreachable), and whether each pose was reachable, (n,) bool."""
        ...

    def reset_joints(self, q: np.ndarray) -> None:
        """Teleport the joints to ``q`` at rest and hold them there."""
        ...

    def command(
        self, q_target: Sequence[float] | np.ndarray, qd_target: Sequence[float] | np.ndarray
    ) -> None:
        """Joint position targets (rad) with feed-forward velocities (rad/s) for the next
        physics step."""
        ...

    def joint_positions(self) -> np.ndarray:
        """Measured joint positions (n_joints,), rad."""
        ...

    def tcp_transform(self) -> np.ndarray:
        """Current TCP transform (4, 4) from the simulated joints."""
        ...

    def tcp_pose(self) -> np.ndarray:
        """Current TCP pose (6,)."""
        ...

    def tool_points(self) -> np.ndarray:
        """Points (m, 3) on the tool's surface at the current pose, world frame, m."""
        ...


RobotFactory = Callable[[BulletClient, ToolSpec], Robot]
"""Builds a robot carrying a tool in a simulation's PyBullet client (e.g. `UR5e`)."""


def _box_surface_points(box: ToolBox, count: int) -> np.ndarray:
    """``count`` deterministic points spread over the surface of ``box`` (tool0), (count, 3)."""
    half = np.asarray(box.half_extents)
    centre = np.asarray(box.position)
    # Fibonacci directions projected onto the box surface: deterministic and well spread.
    index = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * index / count)
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * index
    directions = np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1
    )
    # scale each ray so it hits the box surface
    scale = np.min(half[None, :] / np.maximum(np.abs(directions), 1e-9), axis=1)
    return centre + directions * scale[:, None]


@lru_cache(maxsize=8)
def tool_urdf_path(tool: ToolSpec) -> str:
    """Path of a URDF = airo-models UR5e + ``tool`` (written once per process and tool)."""
    arm_dir = Path(airo_models.__file__).resolve().parent / "arms" / "ur5e"
    text = (arm_dir / "ur5e.urdf").read_text()
    text = text.replace('filename="visual/', f'filename="{arm_dir}/visual/')
    text = text.replace('filename="collision/', f'filename="{arm_dir}/collision/')
    tiny_inertial = (
        '<inertial><mass value="0.001"/><origin xyz="0 0 0"/>'
        '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial>'
    )
    for name in ("base_link", "base", "flange", "tool0"):
        text = text.replace(f'<link name="{name}"/>', f'<link name="{name}">{tiny_inertial}</link>')
    parts = []
    for box in tool.boxes:
        size = " ".join(f"{2 * h:.6f}" for h in box.half_extents)
        xyz = " ".join(f"{p:.6f}" for p in box.position)
        geometry = f'<origin xyz="{xyz}" rpy="0 0 0"/><geometry><box size="{size}"/></geometry>'
        rgba = " ".join(f"{c:.3f}" for c in tool.rgba)
        parts.append(
            f'<visual>{geometry}<material name="tool"><color rgba="{rgba}"/></material></visual>'
        )
        parts.append(f"<collision>{geometry}</collision>")
    inertia = tool.mass * 0.001
    tcp_xyz = " ".join(f"{p:.6f}" for p in tool.tcp_position)
    tool_xml = f"""
    <link name="tool">
      <inertial><mass value="{tool.mass}"/><origin xyz="0 0 0.12"/>
        <inertia ixx="{inertia}" ixy="0" ixz="0" iyy="{inertia}" iyz="0" izz="{inertia}"/>
      </inertial>
      {"".join(parts)}
    </link>
    <joint name="tool0-tool" type="fixed">
      <parent link="tool0"/><child link="tool"/><origin xyz="0 0 0" rpy="0 0 0"/>
    </joint>
    <link name="tcp">{tiny_inertial}</link>
    <joint name="tool-tcp" type="fixed">
      <parent link="tool"/><child link="tcp"/>
      <origin xyz="{tcp_xyz}" rpy="{math.pi:.15f} 0 0"/>
    </joint>
</robot>"""
    text = text.replace("</robot>", tool_xml)
    digest = sha256_hex(text)[:16]
    folder = Path(tempfile.gettempdir()) / f"distgprl-urdf-{os.getuid()}"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"ur5e_{tool.name}_{digest}.urdf"
    if not path.exists():
        atomic_write_text(path, text)
    return str(path)


def _float_list(values: Sequence[float] | np.ndarray) -> list[float]:
    """``values`` as a list of floats (a list is passed through: the control loop's)."""
    return values if isinstance(values, list) else np.asarray(values, dtype=float).tolist()


class UR5e:
    """A UR5e with a tool in one PyBullet client, plus analytic kinematics (a `Robot`).

    Args:
        client: the simulation's PyBullet client.
        tool: the tool mounted on the flange.
        position_gain: PyBullet position-control gain (0..1) of the joint motors.

    Attributes:
        name: ``"ur5e"``.
        body: PyBullet body id.
        joint_indices: PyBullet joint index of each of :data:`JOINT_NAMES`.
        lower_limits, upper_limits: joint limits (6,), rad, from the URDF.
        max_forces: joint effort limits (6,), N m.
        link_index: PyBullet link index by link name (``tool``, ``tcp``, ``base_link_inertia``...).
    """

    name = "ur5e"

    def __init__(self, client: BulletClient, tool: ToolSpec, position_gain: float = 0.6) -> None:
        self.client = client
        self.tool = tool
        self.position_gain = position_gain
        self.body = client.loadURDF(
            tool_urdf_path(tool),
            basePosition=[0.0, 0.0, 0.0],
            baseOrientation=[0.0, 0.0, 1.0, 0.0],  # base_link turned by pi: URDF `base` = world
            useFixedBase=True,
            flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
        )
        names: dict[str, int] = {}
        links: dict[str, int] = {"base_link": -1}
        lower, upper, forces = [], [], []
        for index in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, index)
            names[info[1].decode()] = index
            links[info[12].decode()] = index
        self.joint_indices: tuple[int, ...] = tuple(names[n] for n in JOINT_NAMES)
        for index in self.joint_indices:
            info = client.getJointInfo(self.body, index)
            lower.append(info[8])
            upper.append(info[9])
            forces.append(info[10])
        self.lower_limits = np.asarray(lower)
        self.upper_limits = np.asarray(upper)
        self.max_forces = np.asarray(forces)
        self.link_index = links
        self._last_branch = 0  # `ik_nearest`'s first guess: the branch it chose last
        self.tool_link = links["tool"]
        self.tcp_link = links["tcp"]
        self._tool0_from_tcp = tool.tool0_from_tcp
        self._tcp_from_tool0 = invert_transform(self._tool0_from_tcp)
        self._tool_points_local = np.concatenate(
            [
                _box_surface_points(box, count)
                for box, count in zip(tool.boxes, tool.surface_points_per_box, strict=True)
            ]
        )
        # positional arguments (bodyUniqueId, jointIndices, controlMode, targetPositions,
        # targetVelocities, forces, positionGains, velocityGains): keyword parsing costs
        # a microsecond a physics step
        self._set_motors = client.setJointMotorControlArray
        self._link_state = client.getLinkState  # bound once: a client look-up costs ~1 us
        self._joint_list = list(self.joint_indices)
        self._gains = [position_gain] * 6
        self._velocity_gains = [1.0] * 6
        self._forces = self.max_forces.tolist()
        # the built-in velocity motors of the fixed joints' parents are irrelevant; the six
        # actuated joints are always driven by position control
        for index in range(client.getNumJoints(self.body)):
            client.changeDynamics(self.body, index, linearDamping=0.0, angularDamping=0.0)

    # ------------------------------------------------------------------ kinematics
    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP transform (4, 4) in the world frame for joint positions ``q`` (6,), rad."""
        tool0 = np.asarray(ur_analytic_ik.ur5e.forward_kinematics(*(float(v) for v in q)))
        return tool0 @ self._tool0_from_tcp

    def fk_tool0(self, q: np.ndarray) -> np.ndarray:
        """Flange (tool0) transform (4, 4) in the world frame, official DH kinematics."""
        return np.asarray(ur_analytic_ik.ur5e.forward_kinematics(*(float(v) for v in q)))

    def ik_all(self, tcp_transform: np.ndarray) -> np.ndarray:
        """All analytic IK branches (k, 6), rad, reaching the TCP transform (4, 4).

        Each branch is given by its principal joint values in (-pi, pi] and kept only if
        within the joint limits; k = 0 when the pose is unreachable (up to 8 branches).
        """
        target = np.ascontiguousarray(tcp_transform @ self._tcp_from_tool0)
        solutions = ur_analytic_ik.ur5e.inverse_kinematics(target)
        if not solutions:
            return np.zeros((0, 6))
        branches = np.asarray(solutions, dtype=float).reshape(-1, 6)
        keep = np.all(np.isfinite(branches), axis=1)
        keep &= np.all((branches >= self.lower_limits) & (branches <= self.upper_limits), axis=1)
        return branches[keep]

    def ik_nearest(
        self, tcp_transform: np.ndarray, q_reference: Sequence[float] | np.ndarray
    ) -> np.ndarray | None:
        """The IK solution (6,), rad, nearest to ``q_reference`` (6,), or None if unreachable.

        Each joint of each branch is shifted by a multiple of 2 pi to lie as close as
        possible to the reference within the joint limits (wrap-around), then the branch
        with the smallest Euclidean joint distance is returned (the first of equals).
        """
        # Called once per control period (issue 29): the scalar rule, with the distance of
        # the branch chosen last time as a bound that cuts the other branches short.
        solutions = _inverse_kinematics(tcp_transform @ self._tcp_from_tool0)
        if not solutions:
            return None
        best, self._last_branch = nearest_branch(
            np.array(solutions),
            np.array(q_reference, dtype=float),
            self.lower_limits,
            self.upper_limits,
            self._last_branch,
        )
        return best

    def ik_segment(
        self, poses: np.ndarray, q_reference: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """`ik_nearest` along a segment, in one compiled pass (`distgprl.sim.ur_ik`).

        Args:
            poses: TCP poses (n, 6): x, y, z (m), rotation vector (rad), world frame.
            q_reference: the joint target before the segment (6,), rad.

        Returns (joints (n, 6), rad; reached (n,) bool): pose k's target is the IK branch
        nearest target k - 1 (``q_reference`` for k = 0), the same bits as
        ``ik_nearest(pose_to_matrix(pose_k), target_{k-1})``, or target k - 1 held where pose
        k has no branch within the limits (reached False).
        """
        joints, reached, self._last_branch = segment_ik(
            poses,
            self._tcp_from_tool0,
            q_reference,
            self.lower_limits,
            self.upper_limits,
            self._last_branch,
        )
        return joints, reached

    # ------------------------------------------------------------------ state and control
    def reset_joints(self, q: np.ndarray) -> None:
        """Teleport the joints to ``q`` (6,), rad, at rest, and hold them there."""
        for index, value in zip(self.joint_indices, q, strict=True):
            self.client.resetJointState(self.body, index, float(value), 0.0)
        self.command(np.asarray(q, dtype=float), np.zeros(6))

    def command(
        self, q_target: Sequence[float] | np.ndarray, qd_target: Sequence[float] | np.ndarray
    ) -> None:
        """Position-control targets (6,), rad, with feed-forward velocities (6,), rad/s
        (arrays or lists of floats)."""
        self._set_motors(
            self.body,
            self._joint_list,
            pybullet.POSITION_CONTROL,
            q_target if type(q_target) is list else _float_list(q_target),
            qd_target if type(qd_target) is list else _float_list(qd_target),
            self._forces,
            self._gains,
            self._velocity_gains,
        )

    def joint_positions(self) -> np.ndarray:
        """Measured joint positions (6,), rad."""
        states = self.client.getJointStates(self.body, self.joint_indices)
        return np.array([s[0] for s in states])

    def link_transform(self, link: int) -> np.ndarray:
        """World transform (4, 4) of a link frame (URDF link frame, not the inertial frame)."""
        state = self._link_state(self.body, link, computeForwardKinematics=True)
        return make_transform(quaternion_to_matrix(state[5]), state[4])

    def tcp_transform(self) -> np.ndarray:
        """Current TCP transform (4, 4) in the world frame (from the simulated joints)."""
        return self.link_transform(self.tcp_link)

    def tcp_pose(self) -> np.ndarray:
        """Current TCP pose (6,): x, y, z (m), rx, ry, rz (rotation vector, rad)."""
        return matrix_to_pose(self.tcp_transform())

    def tool_points(self) -> np.ndarray:
        """About 50 points (m, 3) on the tool's surface, world frame, current pose, m."""
        state = self._link_state(self.body, self.tool_link, computeForwardKinematics=True)
        # `link_transform`'s rotation and translation, without the (4, 4) around them
        rotation = quaternion_to_matrix(state[5])
        return self._tool_points_local @ rotation.T + np.array(state[4], dtype=float)

    @property
    def tool_points_local(self) -> np.ndarray:
        """The tool surface points (m, 3) in the tool0 frame, m."""
        return self._tool_points_local.copy()


def base_orientation_check() -> np.ndarray:
    """World-from-base_link rotation (3, 3) used when loading (pi about z)."""
    return rotation_z(math.pi)
