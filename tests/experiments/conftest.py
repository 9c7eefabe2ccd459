"""Fixtures shared by the run tests."""

from __future__ import annotations

import pytest

from distgprl.experiments import training
from distgprl.experiments.training import train_run


@pytest.fixture
def kill_at_the_first_checkpoint(monkeypatch):
    """``kill(root, method="dist-gprl")``: train a 240-step `ci` dcp seed-0 run of ``method``
    under ``root`` and kill it right after its step-120 checkpoint is written (as SIGINT
    would)."""

    def kill(root, method: str = "dist-gprl") -> None:
        original = training.save_checkpoint

        def save_then_die(folder, model, env, extra):
            original(folder, model, env, extra)
            raise KeyboardInterrupt

        monkeypatch.setattr(training, "save_checkpoint", save_then_die)
        with pytest.raises(KeyboardInterrupt):
            train_run(
                "dcp",
                method,
                0,
                preset="ci",
                steps=240,
                root=root,
                show_progress=False,
                evaluate_after=False,
            )
        monkeypatch.setattr(training, "save_checkpoint", original)

    return kill
