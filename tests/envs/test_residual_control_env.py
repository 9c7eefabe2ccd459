"""ProMP-RRL as residual RL (`distgprl.envs.residual_control_env.ResidualRLEnv`, issue 48 item 4;
its ProMP over the 20 expert demonstrations, Protocol v8 rule 3)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.adaptation.residual_control import RL_RATE_HZ, rotation_error
from distgprl.config_types import EnvConfig
from distgprl.envs.residual_control_env import (
    REWARD_TERMS,
    ResidualRLEnv,
    condition_nominal,
    load_nominal_promp,
)
from distgprl.envs.windowed_residual_env import expert_demonstration_set, load_task_promp
from distgprl.methods import METHODS
from distgprl.skill.promp import ObjectCentricProMP


@pytest.fixture(scope="module", params=["dcp", "dbm"])
def env(request):
    env = ResidualRLEnv(request.param)
    yield env
    env.close()


@pytest.fixture(scope="module", params=["dcp", "dbm"])
def one_demo(request):
    env = ResidualRLEnv(request.param, method="promp-rrl-1demo")
    yield env
    env.close()


@pytest.fixture(scope="module")
def dcp():
    env = ResidualRLEnv("dcp")
    yield env
    env.close()


class Recorder:
    """Wraps ``env.sim.execute``: the poses of every call (one per RL step)."""

    def __init__(self, env):
        self.calls: list[np.ndarray] = []
        self._execute = env.sim.execute
        env.sim.execute = self

    def __call__(self, poses, stop_on_collision=False):
        self.calls.append(np.array(poses, copy=True))
        return self._execute(poses, stop_on_collision=stop_on_collision)


def run(env, actions, tc=None, seed=None):
    """One episode of ``actions(step) -> raw action`` on ``tc``: (commanded poses per RL
    step, rewards, infos, observations)."""
    recorder = Recorder(env)
    try:
        obs, _ = env.reset(seed=seed, options=None if tc is None else {"tc": tc})
        observations, rewards, infos = [obs["state"]], [], []
        while True:
            obs, reward, terminated, truncated, info = env.step(actions(len(rewards)))
            observations.append(obs["state"])
            rewards.append(reward)
            infos.append(info)
            if terminated or truncated:
                break
    finally:
        del env.sim.execute  # the instance attribute: the method again
    return recorder.calls, rewards, infos, observations


def test_acts_at_ten_hz_one_execute_per_rl_step(env):
    """RL steps per episode = duration x 10 Hz (48 DCP, 50 DBM); each RL step executes the
    control periods of its 0.1 s, once, in one call: 2 and 3 alternately at 25 Hz, every
    control period of the trajectory exactly once."""
    expected = round(env.duration * RL_RATE_HZ)
    assert env.n_steps == expected == {"dcp": 48, "dbm": 50}[env.task_name]
    calls, rewards, infos, _ = run(env, lambda step: np.zeros(6), env.spec_task.nominal_tc)
    assert len(rewards) == expected and infos[-1]["stopped_at_step"] == -1
    assert [len(c) for c in calls] == [len(s) for s in env.schedule.steps]
    assert {len(c) for c in calls} == {2, 3}
    assert sum(len(c) for c in calls) == round(env.duration / env.sim.control_dt)


def test_zero_action_executes_the_nominal_exactly(env):
    """A zero action commands the conditioned nominal at every control period, bit for bit
    (up to a collision's protective stop), starting from the TCP pose at reset."""
    lengths = []
    for tc in env.spec_task.evaluation_tcs(4):
        calls, _, _, _ = run(env, lambda step: np.zeros(6), tc)
        commanded = np.concatenate(calls)
        lengths.append(len(commanded))
        np.testing.assert_array_equal(commanded, env.nominal_poses[1 : len(commanded) + 1])
    assert max(lengths) == len(env.schedule.tau)  # at least one TC ran to the end
    env.reset(options={"tc": tc})
    start = env.sim.tcp_pose()
    np.testing.assert_array_equal(env.nominal_poses[0, :3], start[:3])
    np.testing.assert_allclose(rotation_error(env.nominal_poses[0], start), 0.0, atol=1e-9)


def test_table_one_nominal_is_the_expert_promp_offset_by_the_object(env):
    """``promp-rrl``: past the start blend the nominal is the 20-demonstration ProMP's mean
    for the TC's object offset conditioned on the start pose (`start_conditioned_mean`),
    which passes through the TCP pose at reset; from one TC to another it moves at the
    interaction time with the object (within 3 cm: the expert's pre-contact pose varies
    with the TC)."""
    tc_a, tc_b = env.spec_task.evaluation_tcs(4)[2:]
    at = np.argmin(np.abs(env._tau - env.spec_task.interaction_time))
    engaged = []
    for tc in (tc_a, tc_b):
        env.reset(options={"tc": tc})
        start = env.sim.tcp_pose()
        offset = np.r_[tc.object_offset, 0.0]
        expected = env.promp.start_conditioned_mean(env._tau, offset, start)
        past_blend = env._tau > env.config.blend_fraction / env.config.n_windows
        np.testing.assert_allclose(env.nominal_poses[past_blend], expected[past_blend], atol=1e-12)
        np.testing.assert_allclose(expected[0, :3], start[:3], atol=2e-3)
        engaged.append(env.nominal_poses[at, :2])
    shift = np.subtract(tc_b.object_offset, tc_a.object_offset)
    np.testing.assert_allclose(engaged[1] - engaged[0], shift, atol=0.03)


def test_promp_rrl_fits_twenty_demonstrations_and_the_study_one(env):
    """Table I's ``promp-rrl`` fits its nominal and its gate on one ProMP over the 20
    expert demonstrations; the study method ``promp-rrl-1demo`` its nominal on the one
    demonstration (its gate on 20 TC-conditioned copies of it, v7); each run's config
    records the count its nominal's ProMP was fitted on."""
    from distgprl.identity import resolve_run

    task = env.task_name
    assert env.promp is env.nominal_promp and env.promp.demonstration_count == 20
    demos, offsets = expert_demonstration_set(task)
    refit = ObjectCentricProMP.fit(demos, offsets)
    np.testing.assert_array_equal(env.promp.weight_mean, refit.weight_mean)
    one = ResidualRLEnv(task, method="promp-rrl-1demo")
    try:
        assert one.nominal_promp is load_nominal_promp(task)
        assert one.nominal_promp.demonstration_count == 1
        assert one.promp is load_task_promp(task, "one")
        counts = {}
        for method, built in (("promp-rrl", env), ("promp-rrl-1demo", one)):
            recorded = resolve_run(task, method, 0, "ci").to_dict()["method"]
            counts[method] = recorded["demonstration_count"]
            assert counts[method] == built.nominal_promp.demonstration_count
        assert counts == {"promp-rrl": 20, "promp-rrl-1demo": 1}
    finally:
        one.close()


def test_one_demo_nominal_is_the_promp_conditioned_by_the_tc_rule(one_demo):
    """``promp-rrl-1demo`` (v7's ProMP-RRL): past the start blend the nominal is
    `condition_nominal` of the one demonstration's ProMP, and at the interaction time it has
    moved with the object by the whole offset (w = 1 there)."""
    env = one_demo
    tc = env.spec_task.evaluation_tcs(4)[3]
    env.reset(options={"tc": tc})
    conditioned = condition_nominal(env.spec_task, env._tau, env._reference, tc)
    past_blend = env._tau > env.config.blend_fraction / env.config.n_windows
    np.testing.assert_allclose(env.nominal_poses[past_blend], conditioned[past_blend], atol=1e-12)
    at = np.argmin(np.abs(env._tau - env.spec_task.interaction_time))
    shift = env.nominal_poses[at, :2] - env._reference[at, :2]
    np.testing.assert_allclose(shift, tc.object_offset, atol=0.01)


@pytest.mark.parametrize("which", ["promp-rrl", "promp-rrl-1demo"])
def test_gate_is_the_promps_own_normalised_std(env, one_demo, which):
    """The gate at each control instant is 1 - sigma / max sigma, sigma the ProMP's positional
    std there (mean over x, y, z): Carvalho et al.'s variability as a decision variable, the
    residual acting where the demonstrations agree (precision) and held back where they
    vary; a larger variance passes less of the residual."""
    env = env if which == "promp-rrl" else one_demo
    sigma = env.promp.trajectory_std(env.schedule.tau)[:, :3].mean(axis=1)
    np.testing.assert_allclose(env.gate, 1.0 - sigma / sigma.max())
    order = np.argsort(sigma, kind="stable")
    assert np.all(np.diff(env.gate[order]) <= 0)
    assert env.gate.min() == 0.0 and env.gate.max() > 0.95


def test_executed_residual_is_the_target_scaled_by_the_gate():
    """With a constant action, once the slew limit has brought the residual to its target,
    the commanded pose differs from the nominal by gate(t) x target at every control period,
    so instants of larger ProMP variance pass less of it (x, y, z each). (Collisions do not
    stop this episode, so it covers the whole trajectory.)"""
    dcp = ResidualRLEnv("dcp", config=EnvConfig(collision_ends_episode=False))
    action = np.array([0.5, -0.4, 0.3, 0.0, 0.0, 0.0])
    tc = dcp.spec_task.evaluation_tcs(5)[4]
    try:
        calls, _, infos, _ = run(dcp, lambda step: action, tc)
    finally:
        dcp.close()
    target = action * dcp.residual_scale
    settled = np.flatnonzero(np.all(np.isclose(infos[-1]["final_parameters"], target), axis=1))
    assert settled[0] == 1  # 0.2 + 0.3 of the range in the first two steps (0.08 + 0.12 s)
    assert len(settled) == dcp.n_steps - 1
    sigma = dcp.promp.trajectory_std(dcp.schedule.tau)[:, :3].mean(axis=1)
    instants, offsets = [], []
    for step in settled[1:]:  # the whole step at the target
        indices = dcp.schedule.steps[step][: len(calls[step])]
        instants.append(indices)
        offsets.append(calls[step][:, :3] - dcp.nominal_poses[indices + 1, :3])
    instants, offsets = np.concatenate(instants), np.concatenate(offsets)
    np.testing.assert_allclose(offsets, dcp.gate[instants, None] * target[None, :3], atol=1e-12)
    expected = (1.0 - sigma[instants] / sigma.max())[:, None] * target[None, :3]
    np.testing.assert_allclose(offsets, expected, atol=1e-12)
    assert np.ptp(sigma[instants]) > 0.5 * sigma.max()  # from certain to uncertain instants


def test_commanded_residual_moves_linearly_within_an_rl_step(dcp):
    """Between RL-step boundaries the commanded residual moves in equal parts per control
    period from the last step's residual to this step's (a first-order hold): it changes per
    control period, and reaches the step's residual at the step's last control period."""
    actions = [np.full(6, 0.1), np.full(6, -0.05), np.zeros(6)]
    calls, _, infos, _ = run(dcp, lambda step: actions[min(step, 2)], dcp.spec_task.nominal_tc)
    residuals = infos[-1]["final_parameters"]
    for step in (1, 2):
        indices = dcp.schedule.steps[step]
        gate = dcp.gate[indices, None]
        commanded = (calls[step][:, :3] - dcp.nominal_poses[indices + 1, :3]) / gate
        fraction = dcp.schedule.fraction[indices, None]
        expected = residuals[step - 1, :3] + fraction * (
            residuals[step, :3] - residuals[step - 1, :3]
        )
        np.testing.assert_allclose(commanded, expected, atol=1e-10)
        np.testing.assert_allclose(commanded[-1], residuals[step, :3], atol=1e-10)


def test_a_promp_without_variance_passes_the_whole_residual():
    """A ProMP with zero variance everywhere (one demonstration, no jitter) gives the gate
    nothing to decide on: it passes the residual whole at every instant (gate 1), so full
    actions move every commanded pose after the first step away from the nominal."""
    from distgprl.envs.residual_control_env import load_nominal_promp

    nominal = load_nominal_promp("dcp")
    flat = ObjectCentricProMP(
        nominal.config,
        nominal.weight_mean,
        np.zeros_like(nominal.weight_covariance),
        nominal.duration,
        1,
    )
    env = ResidualRLEnv("dcp", config=EnvConfig(collision_ends_episode=False), promp=flat)
    try:
        assert np.all(env.gate == 1.0)
        calls, _, _, _ = run(env, lambda step: np.ones(6), env.spec_task.nominal_tc)
        commanded = np.concatenate(calls[1:])
        planned = env.nominal_poses[1 + len(calls[0]) :][: len(commanded)]
        assert np.all(np.abs(commanded[:, :3] - planned[:, :3]).max(axis=1) > 1e-3)
    finally:
        env.close()


def test_reward_terms_sum_to_the_reward_and_read_the_config():
    """Every step's reward is r_progress + r_success + r_collision (in ``info``); the weights
    come from `EnvConfig`: a zero-action success earns progress_weight x progress and the
    success bonus, a colliding episode ends at its collision with -collision_penalty."""
    config = EnvConfig(progress_weight=3.0, success_bonus=5.0, collision_penalty=7.0)
    env = ResidualRLEnv("dcp", config=config)
    try:
        env.reset(options={"tc": env.spec_task.nominal_tc})
        start, rewards, infos = env.sim.task_progress(), [], []
        terminated = False
        while not terminated:
            _, reward, terminated, _, info = env.step(np.zeros(6))
            rewards.append(reward)
            infos.append(info)
        for reward, info in zip(rewards, infos, strict=True):
            assert reward == pytest.approx(sum(info[t] for t in REWARD_TERMS), abs=1e-12)
        assert infos[-1]["success"] and infos[-1]["r_success"] == 5.0
        assert all(info["r_success"] == 0.0 for info in infos[:-1])
        progress = sum(info["r_progress"] for info in infos)
        assert progress == pytest.approx(3.0 * (env.sim.task_progress() - start), abs=1e-9)
        assert sum(rewards) == pytest.approx(progress + 5.0, abs=1e-9)
        rng = np.random.default_rng(0)
        for seed in range(4):
            _, rewards, infos, _ = run(env, lambda step: rng.uniform(-1, 1, 6), seed=seed)
            if infos[-1]["collision"]:
                break
        assert infos[-1]["collision"] and not infos[-1]["success"]
        assert infos[-1]["r_collision"] == -7.0 and infos[-1]["stopped_at_step"] == len(infos) - 1
        assert all(info["r_collision"] == 0.0 for info in infos[:-1])
        assert rewards[-1] == pytest.approx(sum(infos[-1][t] for t in REWARD_TERMS), abs=1e-12)
    finally:
        env.close()


def test_same_seed_same_episode(dcp):
    """reset(seed) draws the same TC, and the same actions then give the same observations,
    rewards and outcome; another seed draws another TC."""

    def episode(seed):
        rng = np.random.default_rng(7)
        return run(dcp, lambda step: rng.uniform(-1, 1, 6), seed=seed)

    first, second = episode(11), episode(11)
    for a, b in zip(first[0], second[0], strict=True):
        np.testing.assert_array_equal(a, b)
    assert first[1] == second[1]
    for a, b in zip(first[3], second[3], strict=True):
        np.testing.assert_array_equal(a, b)
    tc = dcp.tc
    dcp.reset(seed=12)
    assert dcp.tc != tc


def test_episode_row_has_every_evaluation_field(env):
    """`run_episode` (the evaluation and learning curves) reads all it needs from the last
    step's ``info``: the row has every evaluation column, the three adaptation times summing
    to the episode's, the clearances and speeds in their units."""
    from distgprl.experiments.rollout import run_episode
    from distgprl.schema import EVALUATION_FIELDS

    row = run_episode(env, env.spec_task.nominal_tc)
    assert set(EVALUATION_FIELDS) - {"episode"} <= set(row)
    thirds = [row[f"adaptation_ms_w{k}"] for k in (1, 2, 3)]
    assert sum(thirds) == pytest.approx(1000 * sum(env._step_times), rel=1e-12)
    assert row["min_clearance"] >= 0.0 and row["peak_joint_speed"] > 0.0
    assert -1.0 <= row["kinematic_retention"] <= 1.0


def test_observation_is_finite_and_of_the_documented_size(env):
    """24 float32 entries, finite, O(1) at the start (TCP on the nominal, no residual)."""
    obs, _ = env.reset(options={"tc": env.spec_task.nominal_tc})
    state = obs["state"]
    assert (
        state.shape == (24,) and state.dtype == np.float32 and env.observation_space.contains(obs)
    )
    assert np.all(np.isfinite(state))
    np.testing.assert_allclose(state[:12], 0.0, atol=1e-6)  # on the nominal, zero residual
    assert state[18] == 0.0 and state[19] == pytest.approx(env.gate[env.schedule.steps[0][-1]])


def test_method_is_registered_outside_table_one_and_built_by_the_factory():
    """Environment v6: ``promp-rrl`` (Table I's ProMP-RRL) and the ``promp-nominal`` reference
    are residual-control methods; `make_env` builds their environment; v5's windowed-weights
    residual is the exploration method ``promp-rrl-windowed``, which this env refuses."""
    from distgprl.experiments.factories import make_env
    from distgprl.identity import resolve_run
    from distgprl.methods import TABLE_ORDER

    spec = METHODS["promp-rrl"]
    assert spec.action_mode == "residual-control" and spec.label == "ProMP-RRL"
    assert "promp-rrl" in TABLE_ORDER and "promp-rrl-windowed" not in TABLE_ORDER
    assert "promp-rrl-1demo" not in TABLE_ORDER and "promp-nominal-1demo" not in TABLE_ORDER
    for name in ("promp-nominal", "promp-rrl-1demo", "promp-nominal-1demo"):
        assert METHODS[name].action_mode == "residual-control"
    assert METHODS["promp-rrl-windowed"].action_mode == "residual"
    for name in ("promp-rrl", "promp-rrl-1demo"):
        env = make_env(resolve_run("dbm", name, 0, "ci"))
        try:
            assert isinstance(env, ResidualRLEnv) and env.n_steps == 50
        finally:
            env.close()
    with pytest.raises(ValueError, match="not a residual-control method"):
        ResidualRLEnv("dcp", method="promp-rrl-windowed")


def test_ci_training_runs_end_to_end(tmp_path):
    """`distgprl train --preset ci --method promp-rrl` trains 240 RL steps (five
    DCP episodes), records its learning curve at 0, 120 and 240, and evaluates its final and
    best policies on the preset's six evaluation TCs."""
    from typer.testing import CliRunner

    from distgprl.cli import app
    from distgprl.schema import read_csv, read_json

    args = ["train", "--preset", "ci", "--task", "dcp", "--method", "promp-rrl"]
    result = CliRunner().invoke(app, [*args, "--seed", "0", "--root", str(tmp_path)])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "ci" / "dcp" / "promp-rrl" / "seed0"
    _, progress = read_csv(folder / "progress.csv")
    assert [int(row["step"]) for row in progress] == [0, 120, 240]
    _, rows = read_csv(folder / "evaluation.csv")
    assert len(rows) == 6
    assert read_json(folder / "summary.json")["summary"]["episodes"] == 6
    assert (folder / "summary_best.json").exists() and (folder / "done.json").exists()


@pytest.mark.parametrize("method", ["promp-nominal", "promp-nominal-1demo"])
def test_the_nominal_reference_ignores_its_actions(method):
    """``promp-nominal`` (untrained reference) and the study's ``promp-nominal-1demo``
    execute their nominal whatever they are given, as the ``demo`` reference ignores its
    actions; each is the nominal of its trained method."""
    env = ResidualRLEnv("dcp", method=method)
    trained = {"promp-nominal": "promp-rrl", "promp-nominal-1demo": "promp-rrl-1demo"}[method]
    assert env.method.demonstrations == METHODS[trained].demonstrations
    try:
        calls, _, _, _ = run(env, lambda step: np.ones(6), env.spec_task.nominal_tc)
        commanded = np.concatenate(calls)
        np.testing.assert_array_equal(commanded, env.nominal_poses[1 : 1 + len(commanded)])
    finally:
        env.close()
