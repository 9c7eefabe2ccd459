"""`correlation_summary` (distgprl/experiments/skills.py): how strongly S_W acts on a skill."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from distgprl.config_types import EnvConfig
from distgprl.experiments.skills import correlation_summary
from distgprl.skill.gp import GPSkill
from distgprl.skill.kernels import KernelParams

PAPER_WINDOWS = ([1, 2, 3, 4, 5], [5, 6, 7, 8, 9], [9, 10, 11, 12, 13])


AXIS_SCALE = np.array([0.06, 0.2, 0.09, 0.0, 0.0, 0.0])  # like the DCP demonstration's
UNIT = EnvConfig(covariance_scale="unit")
SIGNAL = EnvConfig(covariance_scale="signal", action_scale_rule="fixed")
"""v5's operator (the ``operator-signal`` study reading) with v5's fixed action scales."""


def make_skill(length_scale: float) -> GPSkill:
    rng = np.random.default_rng(0)
    return GPSkill(
        kernel=KernelParams(length_scale, 0.3, 1e-6),
        via_times=np.linspace(0.0, 1.0, 15),
        via_points=rng.normal(size=(15, 6)) * 0.1,
        prior_mean=np.zeros(6),
        duration=4.0,
        axis_scale=AXIS_SCALE,
    )


def independent_window_operator(length_scale, correlation_lambda, window):
    """The principal block of S = K (K + lambda I)^-1, K the unit-variance SE kernel matrix."""
    tau = np.linspace(0.0, 1.0, 15)
    k = np.exp(-((tau[:, None] - tau[None, :]) ** 2) / (2 * length_scale**2))
    s = k @ np.linalg.inv(k + correlation_lambda * np.eye(15))
    return s[np.ix_(window, window)]


@pytest.mark.parametrize(("length_scale", "correlation_lambda"), [(0.06, 1e-2), (0.2, 1e-1)])
def test_summary_describes_the_paper_windows_of_the_independent_operator(
    length_scale, correlation_lambda
):
    config = EnvConfig(correlation_lambda=correlation_lambda, covariance_scale="unit")
    summary = correlation_summary(make_skill(length_scale), config)
    assert [w["via_points"] for w in summary["windows"]] == list(PAPER_WINDOWS)
    for window, reported in zip(PAPER_WINDOWS, summary["windows"], strict=True):
        s_w = independent_window_operator(length_scale, correlation_lambda, window)
        eigenvalues = np.linalg.eigvalsh(0.5 * (s_w + s_w.T))
        assert reported["eigenvalue_min"] == pytest.approx(eigenvalues.min(), abs=1e-8)
        assert reported["eigenvalue_max"] == pytest.approx(eigenvalues.max(), abs=1e-8)
        off = np.abs(s_w - np.diag(np.diag(s_w))).max()
        assert reported["max_off_diagonal"] == pytest.approx(off, abs=1e-8)
    assert summary["via_point_spacing"] == pytest.approx(1 / 14)
    assert summary["neighbour_correlation"] == pytest.approx(
        np.exp(-((1 / 14) ** 2) / (2 * length_scale**2))
    )


def test_a_length_scale_below_the_spacing_leaves_s_w_near_the_identity():
    """With l < the via-point spacing and lambda = 1e-2 (the fitted demonstrations' case),
    the unit-variance S_W (v4) shrinks a raw action by under 10 % and moves no neighbour by
    more than 3 %."""
    summary = correlation_summary(make_skill(0.06), UNIT)
    assert min(w["eigenvalue_min"] for w in summary["windows"]) > 0.9
    assert max(w["max_off_diagonal"] for w in summary["windows"]) < 0.03


def test_near_the_spacing_longer_length_scales_and_larger_lambdas_correlate_more():
    """Around l = the via-point spacing (1/14) the transform's strength rises steeply with l
    and with lambda: more off-diagonal coupling, more shrink of the weakest direction."""

    def strength(length_scale, correlation_lambda):
        summary = correlation_summary(
            make_skill(length_scale),
            EnvConfig(correlation_lambda=correlation_lambda, covariance_scale="unit"),
        )
        windows = summary["windows"]
        return (
            max(w["max_off_diagonal"] for w in windows),
            1.0 - min(w["eigenvalue_min"] for w in windows),
        )

    for a, b in [((0.05, 1e-2), (0.07, 1e-2)), ((0.07, 1e-2), (0.09, 1e-2))]:
        assert all(x < y for x, y in zip(strength(*a), strength(*b), strict=True))
    for a, b in [((0.08, 1e-3), (0.08, 1e-2)), ((0.08, 1e-2), (0.08, 1e-1))]:
        assert all(x < y for x, y in zip(strength(*a), strength(*b), strict=True))


def test_summary_follows_the_env_window_size():
    config = dataclasses.replace(UNIT, window_size=4, n_windows=4)
    summary = correlation_summary(make_skill(0.1), config)
    assert [w["via_points"] for w in summary["windows"]] == [
        [1, 2, 3, 4],
        [4, 5, 6, 7],
        [7, 8, 9, 10],
        [10, 11, 12, 13],
    ]


def test_a_configured_length_scale_replaces_the_fitted_one_in_s_only():
    """`correlation_length_scale` builds S_W from K with that length scale (checked against
    the independent operator); the skill's own kernel, and so its trajectory, is unchanged."""
    skill = make_skill(0.06)
    config = EnvConfig(correlation_length_scale=0.1, covariance_scale="unit")
    summary = correlation_summary(skill, config)
    assert summary["length_scale"] == 0.1
    for window, reported in zip(PAPER_WINDOWS, summary["windows"], strict=True):
        s_w = independent_window_operator(0.1, 1e-2, window)
        off = np.abs(s_w - np.diag(np.diag(s_w))).max()
        assert reported["max_off_diagonal"] == pytest.approx(off, abs=1e-8)
    assert skill.kernel.length_scale == 0.06
    fitted = correlation_summary(skill, UNIT)
    assert fitted["length_scale"] == 0.06
    assert max(w["max_off_diagonal"] for w in summary["windows"]) > 5 * max(
        w["max_off_diagonal"] for w in fitted["windows"]
    )


def independent_axis_operator(length_scale, correlation_lambda, variance, window):
    """The block of S = K (K + lambda I)^-1 for K = variance * the unit SE kernel matrix."""
    tau = np.linspace(0.0, 1.0, 15)
    k = variance * np.exp(-((tau[:, None] - tau[None, :]) ** 2) / (2 * length_scale**2))
    s = k @ np.linalg.inv(k + correlation_lambda * np.eye(15))
    return s[np.ix_(window, window)]


def test_signal_scale_builds_each_axis_from_the_gp_covariance_in_via_point_units():
    """v5: axis a's S_W is built from K_a = sigma_f^2 max(s_a, floor_a)^2 R (checked against an
    independent operator), so axes with a smaller prior variance are shrunk more."""
    from distgprl.adaptation.layout import OBSERVATION_SCALE_FLOOR

    skill = make_skill(0.06)
    summary = correlation_summary(skill, SIGNAL)
    assert summary["covariance_scale"] == "signal"
    variance = 0.3 * np.maximum(AXIS_SCALE, OBSERVATION_SCALE_FLOOR) ** 2
    for window, reported in zip(PAPER_WINDOWS, summary["windows"], strict=True):
        for axis, v in zip(("x", "y", "z", "rx", "ry", "rz"), variance, strict=True):
            s_w = independent_axis_operator(0.06, 1e-2, v, window)
            eigenvalues = np.linalg.eigvalsh(0.5 * (s_w + s_w.T))
            assert reported["axes"][axis]["eigenvalue_min"] == pytest.approx(eigenvalues.min())
            assert reported["axes"][axis]["eigenvalue_max"] == pytest.approx(eigenvalues.max())
    axes = summary["windows"][0]["axes"]
    assert axes["x"]["eigenvalue_max"] < axes["z"]["eigenvalue_max"] < axes["y"]["eigenvalue_max"]
    assert set(summary["candidates"]) == {"signal", "signal-uncoupled", "unit", "none"}
    assert summary["candidates"]["unit"]["eigenvalue_min"] > 0.9


def test_shipped_skills_are_correlated_under_the_v5_operator():
    """The shipped demonstrations' S_W under the v5 scale: smallest eigenvalue not above 0.9
    (issue 30's bar for an operator that acts), largest below 1."""
    from distgprl.envs.tasks import load_task_skill

    for task in ("dcp", "dbm"):
        summary = correlation_summary(load_task_skill(task), SIGNAL)
        low = min(w["eigenvalue_min"] for w in summary["windows"])
        high = max(w["eigenvalue_max"] for w in summary["windows"])
        assert low <= 0.9 and high < 1.0, (task, low, high)


def test_a_skill_without_axis_scale_cannot_build_the_signal_operator():
    skill = dataclasses.replace(make_skill(0.06), axis_scale=None)
    with pytest.raises(ValueError, match="axis_scale"):
        correlation_summary(skill, SIGNAL)
    assert set(correlation_summary(skill, UNIT)["candidates"]) == {"unit", "none"}


def test_reach_is_the_largest_via_point_move_of_a_saturated_action():
    """An axis's reach is max_i sum_j |S_W[i, j]| times the action scale: what the raw action
    with entries sign(S_W[i, j]) (all saturated) moves via-point i by, and no action in
    [-1, 1] moves a via-point farther (checked with random saturated actions). Without the
    transform it is the action scale; under the v5 operator it is smaller."""
    from distgprl.adaptation.layout import build_action_layout
    from distgprl.methods import get_method

    skill, config = make_skill(0.06), SIGNAL
    summary = correlation_summary(skill, config)
    layout = build_action_layout(skill, config, get_method("dist-gprl"))
    rng = np.random.default_rng(3)
    for step, window in enumerate(summary["windows"]):
        for a, axis in enumerate(("x", "y", "z", "rx", "ry", "rz")):
            operator = layout.operators[step, a]
            row = int(np.abs(operator).sum(axis=1).argmax())
            raw = np.zeros((len(window["via_points"]), 6))
            raw[:, a] = np.sign(operator[row])
            best = abs(layout.delta(step, raw.ravel())[row, a])
            assert window["axes"][axis]["reach"] == pytest.approx(best)
            random = rng.choice([-1.0, 1.0], size=(200, *raw.shape))
            moves = [np.abs(layout.delta(step, r.ravel())[:, a]).max() for r in random]
            assert max(moves) <= window["axes"][axis]["reach"] + 1e-12
    scale = dict(zip(("x", "y", "z", "rx", "ry", "rz"), layout.scale, strict=True))
    assert summary["candidates"]["none"]["reach"] == pytest.approx(scale)
    assert summary["reach"] == summary["candidates"]["signal"]["reach"]
    for axis in scale:
        assert summary["reach"][axis] < scale[axis]
        assert summary["reach"][axis] == max(w["axes"][axis]["reach"] for w in summary["windows"])


def test_shipped_skills_reach_their_tc_range_under_the_table_one_operator():
    """Environment v6 (rule "reach"): with each task's TC range, `correlation_summary`
    reports the Table I (zero-mean) operator, and every window via-point's one-step reach is
    at least max(TC range, 0.1 m) on x, y and z (0.05 rad on rotations); NoCov's reach is the
    action scale itself, at least as large."""
    from distgprl.envs.tasks import load_task_skill
    from distgprl.sim.tasks import get_task

    for task in ("dcp", "dbm"):
        tc_range = np.asarray(get_task(task).tc_range)
        summary = correlation_summary(load_task_skill(task), EnvConfig(), tc_range=tc_range)
        assert summary["covariance_scale"] == "zero-mean"
        assert summary["action_scale_rule"] == "reach"
        needed = dict(zip(("x", "y", "z"), np.maximum(tc_range, 0.1), strict=True))
        needed.update(rx=0.05, ry=0.05, rz=0.05)
        for axis, value in needed.items():
            assert summary["reach_min"][axis] == pytest.approx(value, rel=1e-9), (task, axis)
            assert summary["candidates"]["none"]["reach"][axis] >= value - 1e-12
        assert set(summary["candidates"]) == {
            "zero-mean",
            "signal",
            "unit",
            "correlation",
            "signal-uncoupled",
            "none",
        }
        control, signal = summary["candidates"]["signal-uncoupled"], summary["candidates"]["signal"]
        for axis in needed:  # the control: the signal reading's reach, no coupling
            assert control["reach"][axis] == pytest.approx(signal["reach"][axis], rel=1e-12)


DERIVED_NUMBERS = """
import hashlib, json
import numpy as np
from distgprl.adaptation.layout import COVARIANCE_SCALES, build_action_layout
from distgprl.config_types import EnvConfig
from distgprl.envs.tasks import load_task_skill, task_hap_config
from distgprl.experiments.mechanisms import layout_reach
from distgprl.experiments.skills import correlation_summary, task_tc_range
from distgprl.machine import numerics_fingerprint
from distgprl.methods import get_method

def digest(values):
    return hashlib.sha256(np.ascontiguousarray(values, dtype=float).tobytes()).hexdigest()

out = {}
for task in ("dcp", "dbm"):
    skill, tc_range = load_task_skill(task), task_tc_range(task)
    for scale in COVARIANCE_SCALES:
        config = EnvConfig(covariance_scale=scale)
        for method in ("dist-gprl", "dist-gprl-nocov", "gprl"):
            layout = build_action_layout(skill, config, get_method(method), tc_range=tc_range)
            out[f"{task}/{scale}/{method}/S"] = digest(layout.operators)
            out[f"{task}/{scale}/{method}/scale"] = digest(layout.scale)
            reach = layout_reach(layout)
            out[f"{task}/{scale}/{method}/reach"] = digest([reach[k] for k in sorted(reach)])
    summary = correlation_summary(skill, EnvConfig(), tc_range=tc_range)
    out[f"{task}/summary"] = json.dumps(
        [summary["reach"], summary["reach_min"], summary["action_scale"],
         {k: v["reach"] for k, v in summary["candidates"].items()}]
    )
    out[f"{task}/hap_config"] = repr(task_hap_config(task))
print(json.dumps({"numerics": numerics_fingerprint(), "numbers": out}))
"""


def machine_variants() -> dict[str, dict[str, str]]:
    """The numerics to compare: the default, OpenBLAS' AVX2 kernel (``Haswell``), its AVX-512
    kernel (``SkylakeX``, on a CPU that has AVX-512) and an AVX2 machine as far as this one
    can stand in for it (Haswell kernel, numpy's AVX-512 loops disabled)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    avx512 = [t for t in __cpu_dispatch__ if __cpu_features__.get(t) and "AVX2" not in t]
    avx512 = [t for t in avx512 if "512" in t or t == "X86_V4"]
    variants = {"default": {}, "haswell": {"OPENBLAS_CORETYPE": "Haswell"}}
    if __cpu_features__.get("AVX512F"):
        variants["skylakex"] = {"OPENBLAS_CORETYPE": "SkylakeX"}
    if avx512:
        variants["avx2-machine"] = {
            "OPENBLAS_CORETYPE": "Haswell",
            "NPY_DISABLE_CPU_FEATURES": " ".join(avx512),
        }
    return variants


def test_numbers_derived_from_the_committed_skills_are_the_same_under_every_kernel():
    """Protocol v8 rule 7 (issue 68): loading the committed skills, the operator S of every
    reading and method, the action scales, the mechanism table's reach, `correlation_summary`'s
    reach and the HAP grid are identical bit for bit under the default BLAS kernel, OpenBLAS'
    Haswell (AVX2) and SkylakeX (AVX-512) kernels and with numpy's AVX-512 loops disabled,
    each in its own process (the variants are checked to take effect)."""
    import json
    import os
    import subprocess
    import sys

    results = {}
    for name, variables in machine_variants().items():
        env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE",)}
        env.pop("NPY_DISABLE_CPU_FEATURES", None)
        completed = subprocess.run(
            [sys.executable, "-c", DERIVED_NUMBERS],
            env={**env, **variables},
            capture_output=True,
            text=True,
            check=True,
        )
        results[name] = json.loads(completed.stdout.strip().splitlines()[-1])
    assert results["haswell"]["numerics"].startswith("openblas-Haswell_")
    if "skylakex" in results:
        assert results["skylakex"]["numerics"].startswith("openblas-SkylakeX_")
    if "avx2-machine" in results:
        assert "512" not in results["avx2-machine"]["numerics"]
    reference = results["default"]["numbers"]
    assert len(reference) == 2 * (5 * 3 * 3 + 2)
    for name, result in results.items():
        differing = sorted(k for k, v in result["numbers"].items() if reference.get(k) != v)
        assert not differing, (name, result["numerics"], differing)
