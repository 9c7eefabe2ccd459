"""Fixtures of the report tests: finished study runs stamped with the current config hash."""

from __future__ import annotations

import pytest

from distgprl.schema import PROGRESS_FIELDS, write_csv, write_json

EPISODE = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
EPISODE += ("obstacle_offset_y", "success", "collision")
"""Columns of the minimal evaluation.csv of a finished, evaluated run."""


def write_study_run(root, preset, task, method, seed, success, best=None):
    """A finished run of a shipped preset, its files stamped with the current config hash:
    curve points every 1 500 steps from step 0 with ``success``, the final policy's success
    the last point's, the best policy's ``best`` (default: the same)."""
    from distgprl.report.runs import current_hash

    folder = root / preset / task / method / f"seed{seed}"
    config_hash = current_hash(task, method, seed, preset)
    rows = []
    for index, value in enumerate(success):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=1500 * index, success_rate=value, collision_rate=0.0, mean_return=value)
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS, config_hash=config_hash)
    for name, value in (("summary.json", success[-1]), ("summary_best.json", best)):
        summary = {"success_rate": success[-1] if value is None else value, "collision_rate": 0.0}
        write_json(folder / name, {"summary": summary}, config_hash=config_hash)
    evaluation = [{**dict.fromkeys(EPISODE, 0), "success": 1}]
    write_csv(folder / "evaluation.csv", evaluation, EPISODE, config_hash=config_hash)
    write_json(folder / "done.json", {"steps": 1500 * (len(success) - 1)}, config_hash=config_hash)


@pytest.fixture
def study_run():
    """`write_study_run`, for tests that build their own study trees."""
    return write_study_run


@pytest.fixture
def study_tree(tmp_path):
    """DCP: Table I's Dist-GPRL seeds 0 and 1 (seed 1 learns late), NoCov seed 0, Dist-GPRL
    under operator-signal seed 0 (learns early); operator-unit and -correlation not run."""
    write_study_run(tmp_path, "paper", "dcp", "dist-gprl", 0, [0.4, 0.0, 0.0, 0.0])
    write_study_run(tmp_path, "paper", "dcp", "dist-gprl", 1, [0.0, 0.0, 0.0, 0.8])
    write_study_run(tmp_path, "paper", "dcp", "dist-gprl-nocov", 0, [0.0, 0.0, 0.0, 0.0])
    write_study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 0, [0.5, 0.8, 0.9, 0.9])
    return tmp_path


UNIT_PRESET = "unit-study-20"
"""The preset of `unit_study`'s one reading (`unit_study_preset` registers it)."""


def unit_study():
    """A study of every trained method (``acts_on="trainable"``, as a reward constant's): one
    reading, r_tc in twentieths of a task, beside Table I's tenths. No such study ships (the
    reward-unit study is v7's, archived); it stands for any second study of another kind."""
    from distgprl.methods import EXPLORATION_METHODS, METHODS, STUDY_METHODS
    from distgprl.studies import Reading, Study, table_one_reading

    others = EXPLORATION_METHODS + STUDY_METHODS

    return Study(
        name="unit",
        reference=table_one_reading("r_tc in tenths of a task"),
        readings=(
            Reading(UNIT_PRESET, "r_tc in twentieths of a task", (("env.progress_weight", 20.0),)),
        ),
        methods=tuple(m for m, spec in METHODS.items() if spec.trainable and m not in others),
        question="Does a claim hold under another unit of r_tc?",
        acts_on="trainable",
    )


@pytest.fixture
def unit_study_preset(tmp_path_factory, monkeypatch):
    """`unit_study`, its reading's preset registered for this test (`register_preset`) and
    the study read beside ``paper`` (in `distgprl.studies.STUDIES`)."""
    from distgprl import config as config_module
    from distgprl import studies

    monkeypatch.setenv(config_module.USER_PRESETS_ENV, "")
    path = tmp_path_factory.mktemp("presets") / f"{UNIT_PRESET}.yaml"
    path.write_text("extends: paper\nenv: {progress_weight: 20.0}\n")
    config_module.register_preset(path)
    study = unit_study()
    monkeypatch.setitem(studies.STUDIES, study.name, study)
    return study
