"""The method registry describes every method by data (DESIGN §6)."""

from __future__ import annotations

import pytest

from distgprl.agents.methods import METHODS, TABLE_ORDER, get_method
from distgprl.errors import UserInputError


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
    assert METHODS["promp-rrl"].action_mode == "residual"
    assert not METHODS["demo"].trainable


def test_table_order_covers_every_method_once():
    assert sorted(TABLE_ORDER) == sorted(METHODS)


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
    assert "episode_range" not in windowed
    assert windowed == {
        k: v for k, v in asdict(METHODS["dist-gprl"]).items() if k != "episode_range"
    }
    assert METHODS["gprl"].to_dict()["episode_range"] is True
