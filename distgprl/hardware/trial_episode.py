"""One hardware trial as named stages (`one_trial`), for `distgprl.hardware.trials.run_trials`:
set the cell up, perceive, start the episode on the perceived bars, run its decisions through
the episode loop (`distgprl.envs.episode`: the robot or a dry run's prediction as the world
(`distgprl.hardware.worlds`), the protocol's gate (`distgprl.safety_layer.gates`) before it),
judge it."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from distgprl.envs.episode import execute_segment
from distgprl.hardware.adapter import TrialAdapter, adapt, begin_trial, observe
from distgprl.hardware.perception import OBJECTS, MarkerPerception, pose_error
from distgprl.hardware.trial_rows import finish_row, judge_row
from distgprl.hardware.worlds import DryRunWorld, RobotWorld
from distgprl.limits import SafetyLimits
from distgprl.safety_layer.gates import CheckGate, RepairGate, UncheckedGate
from distgprl.safety_layer.plan_check import UnsafePlanError, check_plan
from distgprl.safety_layer.retime import RepairConfig
from distgprl.safety_layer.window_check import describe_repair
from distgprl.schema import TRIAL_FIELDS
from distgprl.trial_protocol import PROTECTIVE_STOP

__all__ = ["TrialSetup", "one_trial"]


@dataclass(frozen=True)
class TrialSetup:
    """What every trial of a `run_trials` call shares (its arguments, resolved)."""

    robot: Any
    perception: MarkerPerception
    adapter: TrialAdapter
    policy: Callable | None
    limits: SafetyLimits
    dry_run: bool
    judge: str
    force: bool
    ask: Callable[[str], str]
    echo: Callable[[str], None]
    repair_config: RepairConfig | None
    paper: bool

    @property
    def twin(self) -> bool:
        return bool(self.robot.name == "twin")


@dataclass
class _TrialRecord:
    """A trial's row and what its bookkeeping columns are made from (`finish_row`)."""

    row: dict[str, Any]
    start: float = field(default_factory=time.perf_counter)
    # seconds, but "perception": the detections' times (ms) (`trial_rows.finish_row`)
    timings: dict[str, Any] = field(
        default_factory=lambda: {"perception": [], "policy": 0.0, "check": 0.0, "execution": 0.0}
    )
    errors: list[tuple[float, float]] = field(default_factory=list)
    planned: float = np.inf

    def finish(self, judge_skip: bool = False) -> dict[str, Any]:
        return finish_row(
            self.row, self.start, self.timings, self.errors, self.planned, judge_skip=judge_skip
        )


def one_trial(setup: TrialSetup, index: int, tc) -> dict[str, Any]:
    """One trial (the module docstring's stages): set the cell up, perceive, start the
    episode, run its decisions through the episode loop, judge it."""
    row: dict[str, Any] = dict.fromkeys(TRIAL_FIELDS, "")
    row.update(trial=index, status="ok", images=0)
    record = _TrialRecord(row)
    setup.perception.reset_tracks()
    setup.adapter.world.tracks.clear()
    if not _set_up_cell(setup, index, tc, row):
        return record.finish(judge_skip=True)

    def perceive() -> bool:
        return _perceive(setup, record)

    if not perceive():
        row.update(status="not_perceived", stop_reason="a bar was not detected at the start")
        return record.finish(judge_skip=True)
    world, gate = _start_episode(setup, row)
    _run_decisions(setup, index, record, world, gate, perceive)
    row["repair"] = ";".join(r.decision for r in gate.reviews)
    row["repair_added_s"] = ";".join(f"{r.time_added:.3f}" for r in gate.reviews)
    row["repair_displacement_m"] = ";".join(f"{r.displacement:.4f}" for r in gate.reviews)
    if setup.dry_run:
        if row["status"] == "ok":
            row["status"] = "planned"
        return record.finish()
    judge_row(
        row,
        setup.robot,
        setup.adapter,
        twin=setup.twin,
        judge=setup.judge,
        ask=setup.ask,
        index=index,
        perceive=perceive,
    )
    return record.finish()


def _set_up_cell(setup: TrialSetup, index: int, tc, row: dict[str, Any]) -> bool:
    """Set the cell up for trial ``index``: the twin on ``tc``; the real robot with the
    operator's bars, driven to its start configuration (a dry run leaves it where it is).
    False if the robot stopped on the way (the row says why)."""
    robot, adapter = setup.robot, setup.adapter
    if setup.twin:
        robot.start_trial(tc)
        row["true_object_offset_y"] = tc.object_offset[1]
        row["true_obstacle_offset_y"] = tc.obstacle_offset[1]
        return True
    if setup.dry_run:  # a dry run plans from wherever the robot is and never moves it
        return True
    setup.ask(f"trial {index + 1}: place both bars on the conveyor, then press Enter ")
    model = adapter.model
    q_home = model.start_joint_positions
    path = np.linspace(robot.joint_positions(), q_home, 50)
    poses = np.array([_fk_pose(model.robot, q) for q in path])
    check_plan(poses, path[0], model.robot, setup.limits, model.control_dt * 4, force=setup.force)
    result = robot.move_joints(q_home)
    if result.stopped:
        row.update(status="stopped", stop_reason=result.stop_reason)
        return False
    return True


def _perceive(setup: TrialSetup, record: _TrialRecord) -> bool:
    """Take an image, fold its detections into the perceived scene with the robot's pose
    (on the twin: the perception error against the truth); True if both bars are tracked."""
    robot, scene = setup.robot, setup.adapter.world
    image, stamp = robot.capture()
    percept = setup.perception.perceive(image, stamp)
    record.timings["perception"].append(percept.detection_ms)
    record.row["images"] += 1
    scene.update(percept)
    scene.set_robot(robot.tcp_pose(), robot.now(), robot.joint_positions())
    if setup.twin:
        truth = robot.sim.object_transforms()
        # the image was taken at `stamp`; compare with the truth predicted back to it
        for name, pose in percept.objects.items():
            true = truth[name].copy()
            if scene.on_belt(true):
                true[:3, 3] -= scene.velocity * (robot.now() - stamp)
            record.errors.append(pose_error(pose.transform, true))
    return all(name in scene.tracks for name in OBJECTS)


def _start_episode(setup: TrialSetup, row: dict[str, Any]):
    """Condition the plan on the perceived bars at the robot's pose: the trial's world
    (the robot, or the dry run's prediction) and the protocol's gate."""
    robot, adapter = setup.robot, setup.adapter
    now = robot.now()
    perceived_tc = begin_trial(adapter, robot.tcp_pose(), now)
    row["object_offset_y"] = round(perceived_tc.object_offset[1], 5)
    row["obstacle_offset_y"] = round(perceived_tc.obstacle_offset[1], 5)
    dt = adapter.model.control_dt
    world: RobotWorld | DryRunWorld = (
        DryRunWorld(adapter.world, dt, now)
        if setup.dry_run
        else RobotWorld(robot, adapter.world, dt)
    )
    return world, _trial_gate(setup, robot.joint_positions(), world.now)


def _trial_gate(setup: TrialSetup, q: np.ndarray, clock: Callable[[], float]):
    """The protocol's gate from joints ``q`` (rad): the paper's (the poses as made), the
    safety layer's check, or its repair; clearance from the perceived scene at ``clock()``."""
    adapter = setup.adapter
    env, scene = adapter.env, adapter.world
    robot, dt = adapter.model.robot, adapter.model.control_dt
    if setup.paper:
        return UncheckedGate(robot, setup.limits, dt, q)
    if setup.repair_config is None:
        return CheckGate(
            robot, setup.limits, dt, q, env.field, scene.obstacle_shapes, clock, setup.force
        )

    def belt() -> np.ndarray | None:
        track = scene.tracks.get("target_bar")
        return scene.velocity if track is not None and scene.on_belt(track.transform) else None

    return RepairGate(
        env,
        robot,
        setup.limits,
        dt,
        q,
        env.field,
        scene.obstacle_shapes,
        clock,
        belt,
        setup.repair_config,
        setup.force,
    )


def _run_decisions(setup, index, record, world, gate, perceive) -> None:
    """The trial's decisions through the episode loop (`distgprl.envs.episode`): update the
    perceived scene, observe, decide, pass the gate, execute; until the last decision, a
    refusal or a stop. An open motion stream is ended at the end."""
    adapter = setup.adapter
    streaming = False  # the robot's stream left open for the next RL step
    for step in range(adapter.trial_steps):
        if step > 0:
            _update_scene(setup, world, gate, step, perceive)
        poses = _decide(setup, record, step)
        # residual control streams its RL steps back to back (the robot's stream is not
        # ended between them); a window plan ends its stream
        last = not adapter.streams_decisions or step == adapter.trial_steps - 1
        checked = gate.seconds
        report = execute_segment(adapter.env, world, step, poses, gate, last).report
        record.timings["check"] += gate.seconds - checked
        _record_review(setup, index, step, record.row, gate.last)
        if report is None:  # refused: nothing of it moved
            break
        record.planned = min(record.planned, gate.last.check.min_clearance)
        if setup.dry_run:
            continue
        streaming = not last and not report.stopped
        if _stopped(record, report):
            break
        if not setup.twin and not streaming:  # a continued stream goes on from its last target
            gate.q = setup.robot.joint_positions()
    if streaming:  # a refusal ended the trial with the robot's stream still open
        setup.robot.stop()


def _decide(setup: TrialSetup, record: _TrialRecord, step: int) -> np.ndarray:
    """The policy's decision ``step`` on the observation of the perceived scene: the
    segment's poses (m, 6) to pass the gate."""
    adapter = setup.adapter
    start = time.perf_counter()
    observation = observe(adapter)
    action = None if setup.policy is None else setup.policy(observation)
    record.timings["policy"] += time.perf_counter() - start
    assert step == adapter.env.step_index  # the env plans its current decision
    return adapt(adapter, action)  # `plan_segment` (the references: a zero action)


def _stopped(record: _TrialRecord, report) -> bool:
    """Record an executed decision; True if the robot stopped (the row says why: a
    controller's limit stop is a failure, not a refusal; a contact is a collision)."""
    record.timings["execution"] += report.wall_s
    if not report.stopped:
        return False
    status = PROTECTIVE_STOP if report.limit_stop else "stopped"
    record.row.update(status=status, stop_reason=report.stop_reason)
    if report.collision:
        record.row["collision"] = 1  # a contact (the real robot: any protective stop)
    return True


def _update_scene(setup: TrialSetup, world, gate, step: int, perceive) -> None:
    """Before decision ``step`` (> 0): a fresh image where the adapter takes one, else the
    robot's pose only (the tracks predict the bars); a dry run's predicted pose and time."""
    if setup.dry_run:
        world.sync_robot(setup.adapter.env.last_commanded, gate.q)
    elif step in setup.adapter.image_steps:
        perceive()
    else:
        world.sync_robot()


def _record_review(setup: TrialSetup, index: int, step: int, row: dict[str, Any], review) -> None:
    """Echo and record the gate's decision for ``step`` (refusals, forced violations)."""
    unit = setup.adapter.decision_unit  # a window, or one 0.1 s RL step (residual RL)
    where = f"trial {index + 1}, {unit} {step + 1}"
    repaired = review.repair
    if repaired is not None and (review.decision != "none" or setup.dry_run):
        setup.echo(f"{where}: {describe_repair(repaired)}")
    if review.refused:
        if repaired is None:
            setup.echo(f"{where}: {review.reason}")
            stop_reason = review.reason
        else:
            stop_reason = f"after retiming and repair: {UnsafePlanError(repaired.remaining)}"
        row.update(
            status="refused",
            refused_limits=",".join(review.refused_limits),
            stop_reason=stop_reason,
        )
    elif review.decision == "refused":  # forced: executed as given, the violations recorded
        row["refused_limits"] = ",".join(review.refused_limits)


def _fk_pose(robot, q: np.ndarray) -> np.ndarray:
    from distgprl.sim.transforms import matrix_to_pose

    return matrix_to_pose(robot.fk(q))
