"""The method registry describes every method by data (DESIGN §6)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from distgprl.errors import UserInputError
from distgprl.identity import resolve_run
from distgprl.methods import (
    EXPLORATION_METHODS,
    METHODS,
    STUDY_METHODS,
    TABLE_ORDER,
    get_method,
)
from distgprl.schema import read_json


def test_registry_matches_the_design_table():
    expected = {
        # name: (action_mode, S transform, distance rewards, HAP, L_sim)
        "gprl": ("global", False, False, False, False),
        "dist-gprl-global": ("global", False, True, True, True),
        "gprl-d": ("window", True, True, False, True),
        "gprl-h": ("window", True, False, True, True),
        "dist-gprl": ("window", True, True, True, True),
        "dist-gprl-nocov": ("window", False, True, True, True),
    }
    for name, row in expected.items():
        spec = METHODS[name]
        got = (
            spec.action_mode,
            spec.covariance_transform,
            spec.distance_rewards,
            spec.hap_prior,
            spec.similarity_loss,
        )
        assert got == row, name
    assert METHODS["gprl"].hold_tc_via_point and METHODS["gprl"].signature_reward
    assert METHODS["gprl"].entropy == "anneal"
    assert METHODS["promp-rrl"].action_mode == "residual-control"  # v6: residual RL
    assert METHODS["promp-rrl-windowed"].action_mode == "residual"
    assert not METHODS["demo"].trainable


def test_table_order_covers_every_method_once():
    """Every method but the exploration and study ones is a Table I row, once; Table I's
    ProMP-RRL and its nominal fit the 20 expert demonstrations (the paper's §V-B), the
    study's one-demonstration pair the one demonstration (environment v7's ProMP-RRL)."""
    outside = set(EXPLORATION_METHODS) | set(STUDY_METHODS)
    assert not set(EXPLORATION_METHODS) & set(STUDY_METHODS)
    assert sorted(TABLE_ORDER) == sorted(set(METHODS) - outside)
    assert METHODS["promp-rrl-expert"].demonstrations == "expert"
    assert METHODS["promp-rrl"].demonstrations == "expert"
    assert METHODS["promp-nominal"].demonstrations == "expert"
    assert not METHODS["promp-nominal"].trainable
    assert STUDY_METHODS == ("promp-rrl-1demo", "promp-nominal-1demo")
    one, v8 = METHODS["promp-rrl-1demo"], METHODS["promp-rrl"]
    assert one.demonstrations == "one" and METHODS["promp-nominal-1demo"].demonstrations == "one"
    assert one.trainable and not METHODS["promp-nominal-1demo"].trainable
    assert replace(one, name=v8.name, label=v8.label, demonstrations="expert") == v8


def test_config_records_how_many_demonstrations_the_promp_is_fitted_on():
    """A run's hashed spec (its config.json) records ``demonstration_count`` for every method
    that fits a ProMP — 20 for Table I's ProMP-RRL, 1 for the study's — and for no other."""
    counts = {
        name: resolve_run("dcp", name, 0, "ci").to_dict()["method"].get("demonstration_count")
        for name in METHODS
    }
    assert counts["promp-rrl"] == counts["promp-nominal"] == counts["promp-rrl-expert"] == 20
    assert counts["promp-rrl-1demo"] == counts["promp-nominal-1demo"] == 1
    assert counts["promp-rrl-windowed"] == 1
    assert {name for name, count in counts.items() if count is None} == {
        name for name, spec in METHODS.items() if not spec.fits_promp
    }
    assert (
        resolve_run("dcp", "promp-rrl", 0, "ci").hash
        != resolve_run("dcp", "promp-rrl-1demo", 0, "ci").hash
    )


def test_study_methods_stay_out_of_the_default_sweep_and_run_by_name():
    """`distgprl sweep --preset paper` plans Table I's 74 runs (7 trained methods x 2 tasks x
    5 seeds, 2 references x 2 tasks) without the study methods; naming one runs it into its
    own folders, results/paper/<task>/promp-rrl-1demo/seed<k>; no study adds it."""
    from distgprl.experiments.sweep import plan_jobs
    from distgprl.studies import STUDIES

    default = plan_jobs("paper")
    assert len(default) == 74
    assert not {job.method for job in default} & set(STUDY_METHODS)
    named = plan_jobs("paper", ["promp-rrl-1demo"])
    assert sorted(job.name for job in named) == sorted(
        f"{task}/promp-rrl-1demo/seed{seed}" for task in ("dcp", "dbm") for seed in range(5)
    )
    assert {job.preset for job in named} == {"paper"}
    reference = plan_jobs("paper", ["promp-nominal-1demo"])
    assert [job.name for job in reference] == [
        "dcp/promp-nominal-1demo/seed0",
        "dbm/promp-nominal-1demo/seed0",
    ]
    for study in STUDIES.values():
        assert not set(study.methods) & set(STUDY_METHODS), study.name


def test_unknown_method_lists_valid_names():
    with pytest.raises(UserInputError, match="valid methods: gprl, promp-rrl"):
        get_method("sac")


def test_global_methods_get_the_windowed_per_episode_range():
    assert {name for name, spec in METHODS.items() if spec.episode_range} == {
        "gprl",
        "dist-gprl-global",
    }


def test_fields_added_later_leave_old_method_hashes_unchanged():
    """A field at its old-behaviour default is not part of the hashed dict: the windowed
    methods' config hashes (and so their committed runs) survive its introduction."""
    from dataclasses import asdict

    windowed = METHODS["dist-gprl"].to_dict()
    assert "episode_range" not in windowed and "demonstrations" not in windowed
    assert windowed == {
        k: v
        for k, v in asdict(METHODS["dist-gprl"]).items()
        if k not in ("episode_range", "demonstrations")
    }
    assert METHODS["promp-rrl-expert"].to_dict()["demonstrations"] == "expert"
    assert "demonstrations" not in METHODS["promp-rrl-1demo"].to_dict()
    assert METHODS["gprl"].to_dict()["episode_range"] is True


PAPER_RESULTS = Path(__file__).resolve().parents[1] / "results" / "paper"


def _finished_paper_runs() -> list[Path]:
    """Run folders ``<task>/<method>/seed<k>`` under results/paper that are complete:
    ``done.json`` for trained methods, ``summary.json`` for the untrained demo."""
    runs = []
    for folder in sorted(PAPER_RESULTS.glob("*/*/seed*")):
        marker = "done.json" if get_method(folder.parent.name).trainable else "summary.json"
        if (folder / marker).exists():
            runs.append(folder)
    return runs


def test_committed_paper_runs_keep_their_config_hash():
    """Every finished committed paper run still resolves to the config hash recorded in its
    config.json (and in its completion marker): a code or preset change that alters the
    hash would orphan the committed results (they would be re-run or mis-attributed)."""
    runs = _finished_paper_runs() if PAPER_RESULTS.is_dir() else []
    if not runs:  # a new environment version's runs archived the old ones (results/archive/)
        pytest.skip(f"{PAPER_RESULTS}: no finished run of this environment version yet")
    mismatches = []
    for folder in runs:
        task, method, seed = folder.parent.parent.name, folder.parent.name, int(folder.name[4:])
        recorded = read_json(folder / "config.json")
        marker = "done.json" if get_method(method).trainable else "summary.json"
        assert read_json(folder / marker)["meta"]["config_hash"] == recorded["config_hash"]
        assert recorded["meta"]["config_hash"] == recorded["config_hash"]
        current = resolve_run(task, method, seed, "paper")
        if current.hash != recorded["config_hash"]:
            now = json.loads(json.dumps(current.to_dict(), default=str))
            changed = sorted(
                f"{part}.{key}"
                for part in ("method", "config")
                for key in {*now[part], *recorded["run"][part]}
                if now[part].get(key) != recorded["run"][part].get(key)
            )
            mismatches.append(
                f"{folder.relative_to(PAPER_RESULTS)}: recorded {recorded['config_hash']}, "
                f"now {current.hash} (changed: {', '.join(changed) or 'task/seed'})"
            )
    assert not mismatches, "\n".join(mismatches)
