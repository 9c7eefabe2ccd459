"""Render episodes to PNG/GIF: the TC-conditioned GP skill alone (the `demo` reference,
`render_demo_episode`), or a trained policy's adapted episode beside the unadapted
demonstration, faded, with its adaptation windows marked (`render_policy_episode`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError

N_EVALUATION_TCS = 100


def render_demo_episode(task: str, tc_index: int | None, out_path: str | Path) -> dict:
    """Execute the GP skill conditioned on evaluation TC ``tc_index`` and write an image.

    Returns the episode summary of `distgprl.sim.render.render_episode`.
    """
    from distgprl.envs.via_point_env import AdaptationEnv
    from distgprl.sim.render import render_episode

    if tc_index is not None and not 0 <= tc_index < N_EVALUATION_TCS:
        raise UserInputError(f"TC index {tc_index} out of range; valid: 0..{N_EVALUATION_TCS - 1}")
    out_path = Path(out_path)
    if out_path.suffix.lower() not in (".png", ".gif"):
        raise UserInputError(f"{out_path}: output must end in .png or .gif")
    if not out_path.parent.is_dir():
        raise UserInputError(f"{out_path}: folder {out_path.parent} does not exist")
    env = AdaptationEnv(task, "demo")
    try:
        spec = env.spec_task
        tc = spec.nominal_tc if tc_index is None else spec.evaluation_tcs(tc_index + 1)[-1]
        env.reset(options={"tc": tc})
        tau = np.concatenate([env.segment_tau(step) for step in range(env.layout.n_steps)])
        poses = env.plan(tau)
    finally:
        env.close()
    return render_episode(task, tc_index, out_path, poses=poses)


WINDOW_COLOURS = ((230, 85, 50), (40, 140, 230), (60, 175, 75), (170, 80, 200), (240, 170, 30))
"""RGB colour of window k (cycled): the frame border and caption of its frames."""

DEMO_FADE = 0.45
"""Weight of the demonstration's pixels in its faded panel (the rest is white)."""


@dataclass(frozen=True)
class RecordedEpisode:
    """Frames of one episode, as `record_episode` captured them.

    Attributes:
        frames: RGB images, each (height, width, 3) uint8: the start, then one every
            ``frame_every`` executed control steps.
        windows: per frame, the 0-based window (RL step) being executed; -1 at the start.
        n_windows: windows of the episode's layout.
        info: the final step's ``info`` (success, collision, min_clearance, ...).
    """

    frames: list[np.ndarray]
    windows: list[int]
    n_windows: int
    info: dict[str, Any]


def evaluation_tc(env, tc_index: int | None):
    """The task's nominal TC (``tc_index`` None) or its evaluation TC ``tc_index``."""
    if tc_index is not None and not 0 <= tc_index < N_EVALUATION_TCS:
        raise UserInputError(f"TC index {tc_index} out of range; valid: 0..{N_EVALUATION_TCS - 1}")
    spec = env.spec_task
    return spec.nominal_tc if tc_index is None else spec.evaluation_tcs(tc_index + 1)[-1]


def record_episode(
    env,
    tc,
    policy: Callable[[dict[str, np.ndarray]], np.ndarray],
    width: int = 480,
    height: int = 360,
    frame_every: int = 4,
) -> RecordedEpisode:
    """Run one episode of ``env`` (an `AdaptationEnv`) on ``tc`` with ``policy`` and keep
    a frame every ``frame_every`` control steps.

    The simulator's ``execute`` is wrapped for the episode: each segment the environment
    executes runs as consecutive pieces of ``frame_every`` poses with a frame after each
    (the same control steps in the same order, so the episode's outcome is the one an
    evaluation of this policy on ``tc`` records), then the wrapper is removed.
    """
    from distgprl.sim.control import SegmentResult

    sim = env.unwrapped.sim
    execute = sim.execute
    frames: list[np.ndarray] = []
    windows: list[int] = []

    def execute_and_film(
        poses: np.ndarray, stop_on_collision: bool = False, **options: Any
    ) -> SegmentResult:
        poses = np.asarray(poses, dtype=float)
        total: SegmentResult | None = None
        for start in range(0, max(len(poses), 1), frame_every):
            part = execute(poses[start : start + frame_every], stop_on_collision, **options)
            frames.append(sim.render_rgb(width, height))
            windows.append(int(env.unwrapped.step_index))
            total = part if total is None else _joined(total, part)
            if stop_on_collision and part.collision:
                break
        assert total is not None
        return replace(total, stopped=total.steps < len(poses))

    sim.execute = execute_and_film
    try:
        obs, _ = env.reset(options={"tc": tc})
        frames.append(sim.render_rgb(width, height))
        windows.append(-1)
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs))
            done = terminated or truncated
    finally:
        del sim.execute  # the class's method again
    return RecordedEpisode(frames, windows, int(env.unwrapped.layout.n_steps), dict(info))


def _joined(first, second):
    """Two consecutive `SegmentResult` pieces as one."""
    return replace(
        first,
        collision=first.collision or second.collision,
        min_clearance=min(first.min_clearance, second.min_clearance),
        ik_failures=first.ik_failures + second.ik_failures,
        steps=first.steps + second.steps,
        peak_joint_speed=max(first.peak_joint_speed, second.peak_joint_speed),
    )


def _outcome(info: dict[str, Any]) -> str:
    if info.get("success"):
        return "success"
    return "collision" if info.get("collision") else "not completed"


def _panel(
    frame: np.ndarray, window: int, n_windows: int, title: str, fade: bool, end: str
) -> np.ndarray:
    """One captioned panel: the frame (faded towards white for the demonstration), a border
    in the colour of its window, ``title`` and ``window k/n`` (or ``start`` / ``end``)."""
    import cv2

    image = frame.astype(np.float64)
    if fade:
        image = DEMO_FADE * image + (1.0 - DEMO_FADE) * 255.0
    image = np.ascontiguousarray(image.astype(np.uint8))
    height, width = image.shape[:2]
    colour: tuple[int, ...] = (
        (120, 120, 120) if window < 0 else WINDOW_COLOURS[window % len(WINDOW_COLOURS)]
    )
    if fade:
        colour = tuple(int(DEMO_FADE * c + (1.0 - DEMO_FADE) * 255) for c in colour)
    cv2.rectangle(image, (0, 0), (width - 1, height - 1), colour, 8)
    stage = end or ("start" if window < 0 else f"window {window + 1}/{n_windows}")
    strip = image[8:64, 8 : min(width - 8, 300)]
    strip[...] = (0.35 * strip + 0.65 * 255).astype(np.uint8)  # a light caption background
    cv2.putText(image, title, (14, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (20, 20, 20), 2)
    cv2.putText(image, stage, (14, 56), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2)
    return image


def compose_frames(
    adapted: RecordedEpisode, demo: RecordedEpisode, adapted_title: str
) -> list[np.ndarray]:
    """Side-by-side frames: the adapted episode (left) and the unadapted demonstration
    (right, faded), each panel marked with its window; the shorter episode holds its last
    frame, which names the outcome. Each frame (height, 2 * width, 3) uint8."""
    count = max(len(adapted.frames), len(demo.frames))
    out = []
    for index in range(count):
        panels = []
        for episode, title, fade in (
            (adapted, adapted_title, False),
            (demo, "demo (unadapted)", True),
        ):
            last = len(episode.frames) - 1
            at = min(index, last)
            stopped = f"window {episode.windows[last] + 1}/{episode.n_windows}"
            end = f"end ({stopped}): {_outcome(episode.info)}" if index >= last else ""
            panels.append(
                _panel(episode.frames[at], episode.windows[at], episode.n_windows, title, fade, end)
            )
        out.append(np.concatenate(panels, axis=1))
    return out


def render_policy_episode(
    env,
    policy: Callable[[dict[str, np.ndarray]], np.ndarray],
    demo_env,
    tc_index: int | None,
    out_path: str | Path,
    title: str,
    frame_every: int = 4,
) -> dict[str, Any]:
    """A trained policy's adapted episode beside the unadapted demonstration, to PNG/GIF.

    Args:
        env: the policy's environment (the run's, `distgprl.experiments.factories.make_env`).
        policy: ``obs -> action`` (e.g. `distgprl.api.Policy`).
        demo_env: the `demo` reference's environment of the same task and preset.
        tc_index: evaluation TC index, or None for the nominal TC.
        out_path: ``.gif`` (every frame, 4 control steps apart) or ``.png`` (the last).
        title: caption of the adapted panel (e.g. ``dist-gprl seed 0``).
        frame_every: control steps between frames.

    Returns:
        ``success``, ``collision``, ``min_clearance`` (m) of the adapted episode, the same
        of the demonstration (``demo_*``), ``frames`` and ``path``.
    """
    import imageio.v3 as iio

    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    if suffix not in (".png", ".gif"):
        raise UserInputError(f"{out_path}: output must end in .png or .gif")
    if not out_path.parent.is_dir():
        raise UserInputError(f"{out_path}: folder {out_path.parent} does not exist")
    tc = evaluation_tc(env, tc_index)
    adapted = record_episode(env, tc, policy, frame_every=frame_every)
    zero = np.zeros(demo_env.action_space.shape, dtype=np.float32)
    demo = record_episode(demo_env, tc, lambda obs: zero, frame_every=frame_every)
    frames = compose_frames(adapted, demo, title)
    try:
        if suffix == ".gif":
            control_dt = env.unwrapped.sim.control_dt
            iio.imwrite(
                out_path, np.stack(frames), duration=int(1000 * frame_every * control_dt), loop=0
            )
        else:
            iio.imwrite(out_path, frames[-1])
    except OSError as exc:
        raise UserInputError(f"{out_path}: cannot write ({exc.strerror or exc})") from exc
    summary: dict[str, Any] = {"tc_index": tc_index}
    for prefix, episode in (("", adapted), ("demo_", demo)):
        summary[f"{prefix}success"] = bool(episode.info.get("success"))
        summary[f"{prefix}collision"] = bool(episode.info.get("collision"))
        summary[f"{prefix}min_clearance"] = float(episode.info.get("min_clearance", np.nan))
    summary.update(frames=len(frames) if suffix == ".gif" else 1, path=str(out_path))
    return summary
