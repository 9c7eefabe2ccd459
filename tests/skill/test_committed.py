"""The committed GP skills (distgprl/skill/committed.py, data/skills/<task>.json; protocol v8
rule 7): read back bit for bit, checked against the shipped demonstration, never refitted
implicitly, and a bad file is a one-line `UserInputError` naming it."""

from __future__ import annotations

import json
import math

import pytest

from distgprl.data import TASK_NAMES
from distgprl.errors import UserInputError
from distgprl.skill.committed import (
    SKILL_DIR,
    committed_skill_path,
    load_committed_skill,
    read_skill_file,
    write_skill_file,
)
from distgprl.skill.gp import FitConfig


def floats(value: object) -> list[float]:
    """Every number of a JSON value, depth first."""
    if isinstance(value, dict):
        return [x for v in value.values() for x in floats(v)]
    if isinstance(value, list):
        return [x for v in value for x in floats(v)]
    return [float(value)] if isinstance(value, int | float) else []


@pytest.mark.parametrize("task", TASK_NAMES)
def test_each_task_ships_its_skill_fitted_under_the_avx2_kernel(task):
    """The package ships ``data/skills/<task>.json`` for every task: the shipped
    demonstration's fit at the default FitConfig (15 via-points, six axis kernels), made under
    OpenBLAS' Haswell (AVX2) kernel with its provenance (commit, numpy, scipy)."""
    committed = read_skill_file(committed_skill_path(task))
    assert committed.path == SKILL_DIR / f"{task}.json"
    assert committed.fit_config == FitConfig()
    skill = load_committed_skill(task)
    assert skill.n_via_points == 15 and skill.name == task
    assert skill.axis_kernels is not None and len(skill.axis_kernels) == 6
    provenance = committed.provenance
    assert provenance["openblas_coretype"] == "Haswell"
    assert provenance["machine"]["numerics"].startswith("openblas-Haswell_")
    assert set(provenance["libraries"]) == {"numpy", "scipy"}
    assert len(provenance["code_commit"].split("+")[0]) == 40


@pytest.mark.parametrize("task", TASK_NAMES)
def test_a_skill_file_reads_back_to_the_same_bits(tmp_path, task):
    """Writing a skill and reading it back gives every number bit for bit (Python's float
    repr round-trips), and the committed file's numbers are those of the skill it loads."""
    skill = load_committed_skill(task)
    path = write_skill_file(task, skill, FitConfig(), tmp_path)
    again = load_committed_skill(task, directory=tmp_path)
    written = floats(json.loads(path.read_text())["skill"])
    assert written == floats(skill.to_dict()) == floats(again.to_dict())
    assert [math.copysign(1, x) for x in written] == [
        math.copysign(1, x) for x in floats(again.to_dict())
    ]
    shipped = floats(json.loads(committed_skill_path(task).read_text())["skill"])
    assert shipped == floats(skill.to_dict())


def corrupt(document: dict, change: str) -> dict:
    """A copy of a skill document with one defect."""
    document = json.loads(json.dumps(document))
    skill = document["skill"]
    if change == "format":
        document["format"] = "something-else"
    elif change == "format_version":
        document["format_version"] = 99
    elif change == "no-skill":
        del document["skill"]
    elif change == "no-kernel":
        del skill["kernel"]
    elif change == "via_points":
        skill["via_points"] = skill["via_points"][:-1]
    elif change == "nan":
        skill["prior_mean"][0] = float("nan")
    elif change == "length_scale":
        skill["kernel"]["length_scale"] = -0.1
    elif change == "axis_kernels":
        skill["axis_kernels"] = skill["axis_kernels"][:5]
    elif change == "via_times":
        skill["via_times"][3] = skill["via_times"][2]
    elif change == "demonstration":
        document["demonstration"]["sha256"] = "0" * 64
    elif change == "task":
        document["task"] = "dbm"
    return document


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ("format", "key 'format'"),
        ("format_version", "key 'format_version'"),
        ("no-skill", "key 'skill'"),
        ("no-kernel", "key 'skill' is malformed"),
        ("via_points", "key 'skill.via_points'"),
        ("nan", "key 'skill.prior_mean'"),
        ("length_scale", "key 'skill.kernel'"),
        ("axis_kernels", "key 'skill.axis_kernels'"),
        ("via_times", "key 'skill.via_times' must increase"),
        ("demonstration", "fitted to a demonstration with sha256"),
        ("task", "key 'task'"),
    ],
)
def test_a_malformed_skill_file_is_a_user_error_naming_it(tmp_path, change, fragment):
    document = json.loads(committed_skill_path("dcp").read_text())
    path = tmp_path / "dcp.json"
    path.write_text(json.dumps(corrupt(document, change)))
    with pytest.raises(UserInputError) as error:
        load_committed_skill("dcp", directory=tmp_path)
    message = str(error.value)
    assert message.startswith(str(path)) and fragment in message, message
    assert "\n" not in message


def test_a_missing_or_unreadable_skill_file_is_a_user_error_naming_it(tmp_path):
    with pytest.raises(UserInputError, match=r"dcp\.json: the committed skill file is missing"):
        load_committed_skill("dcp", directory=tmp_path)
    (tmp_path / "dcp.json").write_text("{not json")
    with pytest.raises(UserInputError, match=r"dcp\.json: not a committed skill file"):
        load_committed_skill("dcp", directory=tmp_path)


def test_another_number_of_via_points_than_committed_is_a_user_error():
    with pytest.raises(UserInputError, match=r"dcp\.json: .* 15 via-points, 10 asked for"):
        load_committed_skill("dcp", 10)


def test_no_code_path_fits_a_skill_implicitly(monkeypatch):
    """With every fitting function replaced by one that raises, the environments (windowed,
    global, ProMP-RRL's residual), the similarity regulariser, the action layout, the
    operator summary, the mechanism table's reach and the HAP grid still build: they read the
    committed skills."""
    import distgprl.skill.committed as committed
    import distgprl.skill.gp as gp
    import distgprl.skill.kernels as kernels
    import distgprl.skill.operator as operator

    def refit(*args, **kwargs):
        raise AssertionError("a skill was fitted implicitly")

    for module, name in (
        (gp, "fit_skill"),
        (committed, "fit_skill"),
        (gp, "fit_kernel"),
        (gp, "fit_zero_mean_axes"),
        (kernels, "minimize"),
        (kernels, "maximum_likelihood_kernel"),
        (operator, "maximum_likelihood_kernel"),
    ):
        monkeypatch.setattr(module, name, refit)
    with pytest.raises(AssertionError, match="implicitly"):  # the patches catch a fit
        committed.fit_task_skill("dcp")

    from distgprl.config_types import EnvConfig
    from distgprl.envs.tasks import load_task_skill, task_hap_config
    from distgprl.experiments.factories import build_regulariser, make_env
    from distgprl.experiments.mechanisms import env_reach
    from distgprl.experiments.skills import correlation_summary, task_tc_range
    from distgprl.identity import resolve_run

    for task in TASK_NAMES:
        correlation_summary(load_task_skill(task), EnvConfig(), tc_range=task_tc_range(task))
        task_hap_config(task)
    for method in ("gprl-d", "gprl", "promp-rrl"):
        run = resolve_run("dcp", method, 0, "ci")
        env = make_env(run)
        try:
            env.reset(seed=0)
            env_reach(env, run.method)
            if method == "gprl-d":
                assert build_regulariser(env, run) is not None
        finally:
            env.close()
