"""`report/` imports neither torch nor pybullet (DESIGN §1): the report modules, and the
schema and identity modules they read results with, import in a process where importing
``torch``, ``pybullet``, ``stable_baselines3`` or ``gymnasium`` raises."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

BLOCKED = ("torch", "pybullet", "pybullet_utils", "stable_baselines3", "gymnasium")

BLOCKER = textwrap.dedent(
    f"""
    import sys

    class Blocker:
        blocked = {BLOCKED!r}

        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in self.blocked:
                raise ImportError(f"blocked import of {{name}}")
            return None

    sys.meta_path.insert(0, Blocker())
    """
)


def run_blocked(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, "-c", BLOCKER + textwrap.dedent(code)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_blocker_blocks():
    """The meta-path blocker makes `import pybullet` and `import torch` raise ImportError."""
    for name in ("pybullet", "torch"):
        result = run_blocked(f"import {name}")
        assert result.returncode != 0
        assert f"blocked import of {name}" in result.stderr


@pytest.mark.parametrize(
    "module",
    [
        "distgprl.report.tables",
        "distgprl.report.table1",
        "distgprl.report.table2",
        "distgprl.report.curves",
        "distgprl.report.seed_curves",
        "distgprl.report.onset_figure",
        "distgprl.report.paired",
        "distgprl.report.runs",
        "distgprl.report.frame",
        "distgprl.report.check",
        "distgprl.report.aggregate",
        "distgprl.report.claims",
        "distgprl.report.markdown",
        "distgprl.schema",
        "distgprl.identity",
    ],
)
def test_report_modules_import_without_torch_or_pybullet(module):
    """Each module imports, and no blocked package ends up in ``sys.modules``."""
    result = run_blocked(
        f"""
        import importlib, sys
        importlib.import_module({module!r})
        loaded = sorted({{m.split(".")[0] for m in sys.modules}} & set({BLOCKED!r}))
        assert not loaded, loaded
        """
    )
    assert result.returncode == 0, result.stderr


def test_current_hash_resolves_without_torch_or_pybullet():
    """The tables check every run's config hash; resolving one needs no simulator or torch,
    and gives the hash this (unblocked) process resolves."""
    from distgprl.identity import resolve_run

    result = run_blocked(
        """
        from distgprl.report.runs import current_hash
        print(current_hash("dbm", "dist-gprl", 1, "paper"))
        """
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == resolve_run("dbm", "dist-gprl", 1, "paper").hash
