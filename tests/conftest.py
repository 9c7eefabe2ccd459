"""Shared fixtures: small, fast, deterministic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

from distgprl.skill.demos import Demonstration, save_demonstration  # noqa: E402


def smooth_demo_poses(times: np.ndarray) -> np.ndarray:
    """A smooth synthetic 6-D trajectory, shape (n, 6), m and rad."""
    tau = (times - times[0]) / (times[-1] - times[0])
    return np.stack(
        [
            0.4 + 0.15 * np.sin(2 * np.pi * 0.7 * tau),
            -0.2 + 0.3 * tau**2,
            0.3 + 0.1 * np.cos(3 * tau),
            np.pi - 0.1 * tau,
            0.05 * np.sin(2 * tau),
            0.2 * tau,
        ],
        axis=1,
    )


@pytest.fixture
def smooth_demo() -> Demonstration:
    times = np.linspace(0.0, 4.0, 401)
    return Demonstration(times=times, poses=smooth_demo_poses(times), name="synthetic")


@pytest.fixture
def smooth_demo_file(tmp_path, smooth_demo):
    path = tmp_path / "synthetic.csv"
    save_demonstration(path, smooth_demo.times, smooth_demo.poses)
    return path


@pytest.fixture(scope="session")
def untrained_dbm_policy(tmp_path_factory):
    """``save(method) -> path``: a freshly constructed (untrained) DBM ``ci`` actor of
    ``method`` saved like a trained run's ``model.zip``, its run's config beside it (the
    hardware trials and the sweep's twin trials run it)."""

    def save(method: str) -> Path:
        # built without the regulariser (only the actor runs in a trial): no HAP subspace
        from distgprl.agents.sac import RegularisedSAC, StateOnlyExtractor
        from distgprl.experiments.factories import make_env
        from distgprl.identity import resolve_run
        from distgprl.schema import write_json

        run = resolve_run("dbm", method, 0, preset="ci")
        env = make_env(run)
        try:
            agent = RegularisedSAC(
                "MultiInputPolicy",
                env,
                buffer_size=100,
                learning_starts=0,
                policy_kwargs={
                    "features_extractor_class": StateOnlyExtractor,
                    "net_arch": list(run.config.sac.net_arch),
                },
                seed=0,
                device="cpu",
            )
            path = tmp_path_factory.mktemp("model") / "model.zip"
            agent.save(path)
            # beside it, as in a run folder: the run's config (its hash goes into the trials)
            write_json(path.parent / "config.json", {"config_hash": run.hash}, kind="config")
        finally:
            env.close()
        return path

    return save
