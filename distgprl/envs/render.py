"""Render an episode of the TC-conditioned GP skill (the `demo` reference) to PNG/GIF."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from distgprl.errors import UserInputError

N_EVALUATION_TCS = 100


def render_demo_episode(task: str, tc_index: int | None, out_path: str | Path) -> dict:
    """Execute the GP skill conditioned on evaluation TC ``tc_index`` and write an image.

    Returns the episode summary of `distgprl.sim.render.render_episode`.
    """
    from distgprl.envs.adaptation import AdaptationEnv
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
        tau = np.concatenate([segment[0] for segment in env._segment_maps])
        poses = env._plan(tau)
    finally:
        env.close()
    return render_episode(task, tc_index, out_path, poses=poses)
