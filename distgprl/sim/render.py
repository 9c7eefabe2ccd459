"""Pictures and animations of task episodes (headless TinyRenderer)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from distgprl.errors import UserInputError
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import TaskConfig, condition_by_translation, resample_to_control


def demo_poses_for_tc(task_name: str, tc_index: int | None) -> tuple[np.ndarray, TaskConfig]:
    """Control-rate TCP poses (k, 6) of the shipped demo conditioned on an evaluation TC.

    ``tc_index`` None means the nominal TC. Conditioning uses the translation stand-in
    :func:`~distgprl.sim.tasks.base.condition_by_translation` (not the GP skill).
    Returns (poses, tc).
    """
    from distgprl.skill.demos import load_demonstration

    spec = get_task(task_name)
    if tc_index is None:
        tc = spec.nominal_tc
    else:
        tcs = spec.evaluation_tcs()
        if not 0 <= tc_index < len(tcs):
            raise UserInputError(f"TC index {tc_index} out of range 0..{len(tcs) - 1}")
        tc = tcs[tc_index]
    demo = load_demonstration(spec.demo_path)
    poses = condition_by_translation(
        demo.times,
        demo.poses,
        np.asarray(tc.object_offset),
        spec.interaction_time,
        goal_fixed_in_world=spec.goal_fixed_in_world,
    )
    return poses, tc


def render_episode(
    task_name: str,
    tc_index: int | None,
    out_path: str | Path,
    poses: np.ndarray | None = None,
    width: int = 480,
    height: int = 360,
    frame_every: int = 4,
) -> dict[str, object]:
    """Execute an episode and write a PNG (last frame) or an animated GIF.

    Args:
        task_name: "dcp" or "dbm".
        tc_index: index into the task's evaluation TCs, or None for the nominal TC.
        out_path: ``.png`` or ``.gif`` file.
        poses: control-rate TCP poses (k, 6) to execute; default: the shipped demo
            conditioned on the TC by translation (:func:`demo_poses_for_tc`).
        width, height: image size in pixels.
        frame_every: GIF frame every this many control steps.
    Returns:
        A summary: success, collision, min_clearance, frames written, path.
    Raises:
        UserInputError: unknown task, TC index out of range, bad suffix, unwritable path.
    """
    import imageio.v3 as iio

    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    if suffix not in (".png", ".gif"):
        raise UserInputError(f"{out_path}: output must end in .png or .gif")
    if not out_path.parent.exists() or not out_path.parent.is_dir():
        raise UserInputError(f"{out_path}: folder {out_path.parent} does not exist")
    spec = get_task(task_name)
    conditioned, tc = demo_poses_for_tc(task_name, tc_index)
    sim = spec.make_sim()
    try:
        if poses is None:
            from distgprl.skill.demos import load_demonstration

            demo = load_demonstration(spec.demo_path)
            poses = resample_to_control(demo.times, conditioned, sim.control_dt)
        poses = np.asarray(poses, dtype=float)
        sim.reset(tc)
        frames = [sim.render_rgb(width, height)] if suffix == ".gif" else []
        collision, min_clearance = False, sim.clearance_cutoff
        for start in range(0, poses.shape[0], frame_every):
            result = sim.execute(poses[start : start + frame_every])
            collision |= result.collision
            min_clearance = min(min_clearance, result.min_clearance)
            if suffix == ".gif":
                frames.append(sim.render_rgb(width, height))
        if suffix == ".png":
            frames = [sim.render_rgb(width, height)]
        success = sim.success()
    finally:
        sim.close()
    try:
        if suffix == ".gif":
            iio.imwrite(out_path, np.stack(frames), duration=int(1000 * frame_every * 0.04), loop=0)
        else:
            iio.imwrite(out_path, frames[0])
    except OSError as exc:
        raise UserInputError(f"{out_path}: cannot write ({exc.strerror or exc})") from exc
    return {
        "task": task_name,
        "tc_index": tc_index,
        "success": bool(success),
        "collision": bool(collision),
        "min_clearance": float(min_clearance),
        "frames": len(frames),
        "path": str(out_path),
    }
