"""The names a trial file records: which trained policy its trials ran."""

from __future__ import annotations

import pytest

from distgprl.errors import UserInputError
from distgprl.trial_protocol import TABLE2_POLICY, TRIAL_POLICIES, check_trial_policy, file_policy


@pytest.mark.parametrize(
    ("provenance", "policy"),
    [
        ({}, None),  # a reference runs no policy
        ({"model": "/r/paper/dbm/gprl/seed0/model.zip"}, "final"),  # predates the name
        ({"model": "/r/other.zip"}, "given"),  # predates the name
        ({"model": "/r/paper/dbm/gprl/seed0/model.zip", "policy": "final"}, "final"),
        ({"model": "/tmp/model.zip", "policy": "given"}, "given"),  # named: --model
        ({"model": "/r/policy_best.pt", "policy": "best (shipped, curve step 300)"}, "best"),
    ],
)
def test_a_trial_files_policy_is_read_from_its_provenance(provenance, policy):
    """The recorded name wins; a file without one is final if it ran a ``model.zip``."""
    assert file_policy({"policy": provenance}) == policy


def test_table_two_counts_a_named_trial_policy_and_an_unknown_one_is_refused():
    assert TABLE2_POLICY in TRIAL_POLICIES
    assert [check_trial_policy(policy) for policy in TRIAL_POLICIES] == list(TRIAL_POLICIES)
    with pytest.raises(UserInputError, match="final, best"):
        check_trial_policy("latest")


def test_a_reference_counts_in_every_table_and_a_given_file_in_table_twos():
    from distgprl.trial_protocol import counts_for

    assert counts_for(None, "final") and counts_for(None, "best")
    assert counts_for("final", "final") and not counts_for("final", "best")
    assert counts_for("best", "best") and not counts_for("best", "final")
    assert counts_for("given", TABLE2_POLICY) and not counts_for("given", "best")
