"""Record a bit-exact trace of paper-preset environment episodes (the bit-exactness reference).

`record_trace` runs fixed-seed episodes with fixed pseudo-random actions and returns every
observation, reward, terminated flag and numeric ``info`` value (timings left out), plus the
simulator's float64 state after every step (joint positions, TCP pose, object pose, clock).

``python tests/envs/_env_trace.py [OUT.npz]`` writes the trace of `TRACE_RUNS` with this
machine's `distgprl.machine.numerics_fingerprint` (default
``tests/envs/data/env_trace_v<ENVIRONMENT_VERSION>_<fingerprint>.npz``). Each environment
version changes bits, so its traces are recorded anew with the code its runs are made with
(v8: on this project's machine, under the Haswell and the SkylakeX OpenBLAS kernel); older
traces are in git history. A CPU with other numerics records its own trace with the same code.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from distgprl.config_types import ENVIRONMENT_VERSION
from distgprl.machine import numerics_fingerprint

DATA = Path(__file__).parent / "data"
FINGERPRINT_KEY = "__fingerprint__"

TRACE_RUNS: tuple[tuple[str, str, int], ...] = (
    ("dcp", "dist-gprl", 10),
    ("dbm", "dist-gprl", 10),
    ("dcp", "promp-rrl", 1),  # v6: residual RL, ~50 RL steps per episode
    ("dbm", "promp-rrl", 1),
    ("dcp", "gprl", 2),
    ("dbm", "gprl", 2),
    ("dcp", "demo", 2),
    ("dbm", "demo", 2),
)
"""(task, method, episodes) of the committed trace."""

#: info keys that are wall-clock timings (not numerics) or not numbers.
SKIPPED_INFO = frozenset({"adaptation_time_s", "tc"})


def trace_fingerprint(path: Path) -> str | None:
    """The fingerprint a trace file was recorded with (None: not recorded)."""
    with np.load(path) as trace:
        return str(trace[FINGERPRINT_KEY]) if FINGERPRINT_KEY in trace.files else None


def _sim_state(sim) -> np.ndarray:
    """The simulator's float64 state: joints (6), TCP pose (6), object position (3) and
    quaternion (4), clock (1)."""
    return np.concatenate(
        [
            sim.joint_positions(),
            sim.tcp_pose(),
            sim.object_position(),
            sim.object_orientation(),
            [sim.time],
        ]
    )


def record_trace(task: str, method: str, episodes: int) -> dict[str, np.ndarray]:
    """Run ``episodes`` episodes (reset seeds 100, 101, ...; actions uniform in [-1, 1] from
    generators seeded 1000, 1001, ...) of the paper preset's env for ``method`` on ``task``.

    Returns arrays keyed ``<task>/<method>/<name>``: ``state``, ``aux`` (every observation,
    the reset's included), ``reward``, ``terminated``, ``sim`` (after every step and reset)
    and ``info/<key>`` (numeric info values of every step, NaN-padded where a step lacks one).
    """
    from distgprl.api import make_env

    env = make_env(task, method, preset="paper")
    prefix = f"{task}/{method}"
    states, auxes, rewards, terminated_flags, sims = [], [], [], [], []
    infos: list[dict[str, np.ndarray]] = []
    try:
        sim = env.unwrapped.sim
        for episode in range(episodes):
            rng = np.random.default_rng(1000 + episode)
            obs, _ = env.reset(seed=100 + episode)
            states.append(obs["state"])
            auxes.append(obs.get("aux", np.zeros(0, dtype=np.float32)))  # none: residual RL
            sims.append(_sim_state(sim))
            done = False
            while not done:
                action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
                obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                states.append(obs["state"])
                auxes.append(obs.get("aux", np.zeros(0, dtype=np.float32)))
                sims.append(_sim_state(sim))
                rewards.append(reward)
                terminated_flags.append(terminated)
                infos.append(
                    {
                        key: np.atleast_1d(np.asarray(value, dtype=float)).ravel()
                        for key, value in info.items()
                        if key not in SKIPPED_INFO
                    }
                )
    finally:
        env.close()
    trace = {
        f"{prefix}/state": np.stack(states),
        f"{prefix}/aux": np.stack(auxes),
        f"{prefix}/reward": np.asarray(rewards, dtype=float),
        f"{prefix}/terminated": np.asarray(terminated_flags, dtype=bool),
        f"{prefix}/sim": np.stack(sims),
    }
    for key in sorted({k for info in infos for k in info}):
        width = max(len(info[key]) for info in infos if key in info)
        rows = np.full((len(infos), width), np.nan)
        for row, info in zip(rows, infos, strict=True):
            if key in info:
                row[: len(info[key])] = info[key]
        trace[f"{prefix}/info/{key}"] = rows
    return trace


def record_all() -> dict[str, np.ndarray]:
    """The trace of every run in `TRACE_RUNS`."""
    out: dict[str, np.ndarray] = {}
    for task, method, episodes in TRACE_RUNS:
        out.update(record_trace(task, method, episodes))
    return out


if __name__ == "__main__":
    trace = record_all()
    # after the episodes: every OpenBLAS the test process loads (numpy's, scipy's) is loaded
    # by then, and the fingerprint names them all
    fingerprint = numerics_fingerprint()
    default = DATA / f"env_trace_v{ENVIRONMENT_VERSION}_{fingerprint}.npz"
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else default
    np.savez_compressed(out, **trace, **{FINGERPRINT_KEY: np.array(fingerprint)})
    print(f"wrote {out} ({fingerprint})")
