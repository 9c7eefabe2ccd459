"""`distgprl.experiments.audit` (issue 52): the comparison of two run folders in every value
but timings, and the audit of a finished run folder, that the cluster test
(`scripts/cluster_test.py`) counts with. On real run folders of a tiny preset: one trained
whole, one killed after its first checkpoint and resumed."""

from __future__ import annotations

import csv
import io
import json
import shutil
import zipfile
from pathlib import Path

import pytest

from distgprl.config import USER_PRESETS_ENV, register_preset
from distgprl.experiments import training
from distgprl.experiments.audit import TIMING_FIELDS, audit_run, compare_runs
from distgprl.experiments.checkpoints import checkpoint_paths
from distgprl.experiments.training import train_run
from distgprl.schema import PROGRESS_FIELDS, read_json

TINY_PRESET = """\
sac:
  learning_starts: 3
  batch_size: 4
  buffer_size: 100
  net_arch: [16, 16]
run:
  total_steps: 18
  eval_every: 6
  curve_episodes: 1
  eval_episodes: 2
  checkpoint_every: 6
"""


@pytest.fixture(scope="module")
def preset(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("preset") / "tiny-audit.yaml"
    path.write_text(TINY_PRESET)
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv(USER_PRESETS_ENV, raising=False)
        patch.delenv("DISTGPRL_CHECKPOINT_ROOT", raising=False)  # checkpoints under tmp
        yield register_preset(path)


def train(root: Path, preset: str, resume: bool = False) -> Path:
    return train_run(
        "dcp", "gprl-h", 0, preset=preset, root=root, show_progress=False, resume=resume
    )


@pytest.fixture(scope="module")
def whole(preset, tmp_path_factory) -> Path:
    """The tiny run trained once, never killed (read only: tests copy it)."""
    return train(tmp_path_factory.mktemp("whole"), preset)


@pytest.fixture(scope="module")
def resumed(preset, tmp_path_factory) -> Path:
    """The same run killed right after its first checkpoint, then resumed."""
    root = tmp_path_factory.mktemp("resumed")
    original = training.save_checkpoint

    def save_then_die(folder, model, env, extra):
        original(folder, model, env, extra)
        raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(training, "save_checkpoint", save_then_die)
        with pytest.raises(KeyboardInterrupt):
            train(root, preset)
    return train(root, preset, resume=True)


@pytest.fixture
def copy(whole, tmp_path) -> Path:
    """A copy of the whole run's folder, to change."""
    return Path(shutil.copytree(whole, tmp_path / "copy"))


def set_cell(path: Path, row: int, column: str, value: str) -> None:
    """Set one cell of a result CSV (its sidecar unchanged)."""
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    rows[row][column] = value
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.write_text(out.getvalue())


def set_key(path: Path, keys: tuple[str, ...], value) -> None:
    document = json.loads(path.read_text())
    target = document
    for key in keys[:-1]:
        target = target[key]
    target[keys[-1]] = value
    path.write_text(json.dumps(document))


def test_a_resumed_run_equals_one_never_killed_in_every_value_but_timings(whole, resumed):
    """Bit-identical weights, curve, evaluations and summaries; only the resume record of
    done.json and the timings differ, and the audit finds both whole."""
    [entry] = read_json(resumed / "done.json")["resumes"]
    assert entry["step"] > 0 and entry["exact"]
    assert read_json(whole / "done.json")["resumes"] == []
    assert compare_runs(whole, resumed) == []
    assert audit_run(whole) == [] and audit_run(resumed) == []


def test_timings_are_ignored_and_every_other_value_is_compared(whole, copy):
    for path, column in [
        ("progress.csv", "wall_time_s"),
        ("evaluation.csv", "policy_ms"),
        ("evaluation.csv", "adaptation_ms_w2"),
    ]:
        set_cell(copy / path, 1 if path == "progress.csv" else 0, column, "12345.0")
    set_key(copy / "summary.json", ("summary", "median_policy_ms_per_episode"), 9.0)
    set_key(copy / "done.json", ("train_cpu_time_s",), 9.0)
    set_key(copy / "done.json", ("meta", "utc_time"), "2000-01-01T00:00:00Z")
    assert compare_runs(whole, copy) == []
    assert {"wall_time_s", "policy_ms", "utc_time"} <= TIMING_FIELDS
    assert "wall_time_s" in PROGRESS_FIELDS

    set_cell(copy / "progress.csv", 2, "mean_return", "0.5")
    set_cell(copy / "evaluation.csv", 1, "success", "7")
    set_key(copy / "summary.json", ("summary", "success_rate"), 0.125)
    set_key(copy / "done.json", ("steps",), 17)
    differences = compare_runs(whole, copy)
    assert any(d.startswith("progress.csv row 3 mean_return:") for d in differences)
    assert any(d.startswith("evaluation.csv row 2 success:") for d in differences)
    assert "summary.json.summary.success_rate: " in "\n".join(differences)
    assert any(d.startswith("done.json.steps: 18 != 17") for d in differences)
    assert len(differences) == 4, differences


def rewrite_member(model: Path, member: str, data: bytes) -> None:
    with zipfile.ZipFile(model) as old:
        members = {name: old.read(name) for name in old.namelist()}
    members[member] = data
    with zipfile.ZipFile(model, "w") as new:
        for name, content in members.items():
            new.writestr(name, content)


def test_the_trained_weights_are_compared_not_the_model_files_notes(whole, copy):
    rewrite_member(copy / "model.zip", "system_info.txt", b"another machine")
    assert compare_runs(whole, copy) == []
    with zipfile.ZipFile(copy / "model.zip") as model:
        weights = bytearray(model.read("policy.pth"))
    weights[-100] ^= 1
    rewrite_member(copy / "model.zip", "policy.pth", bytes(weights))
    assert compare_runs(whole, copy) == ["model.zip: policy.pth differs (the trained weights)"]


def test_a_file_in_one_folder_only_and_a_changed_curve_actor_are_differences(whole, copy):
    (copy / "summary_best.json").unlink()
    [actor] = sorted((checkpoint_paths(copy)["dir"] / "curve_policies").iterdir())[:1]
    actor.write_bytes(actor.read_bytes() + b"\0")
    differences = compare_runs(whole, copy)
    assert f"summary_best.json: only in {whole}" in differences
    assert f"curve_policies/{actor.name}: the bytes differ" in differences


def test_the_audit_finds_duplicated_steps_a_checkpoint_off_its_manifest_and_leftovers(copy):
    progress = (copy / "progress.csv").read_text().splitlines()
    (copy / "progress.csv").write_text("\n".join([*progress, progress[-1]]) + "\n")
    buffer = checkpoint_paths(copy)["buffer"]
    buffer.write_bytes(buffer.read_bytes()[:-1])
    (copy / ".model.tmp.zip").write_bytes(b"")
    problems = audit_run(copy)
    assert any(p.startswith("progress.csv: steps not strictly increasing") for p in problems)
    assert any(p.startswith(f"checkpoint: {buffer} has") for p in problems), problems
    assert "left behind: .model.tmp.zip" in problems
    assert len(problems) == 3, problems


def test_an_unfinished_run_is_not_whole(copy):
    (copy / "done.json").unlink()
    assert audit_run(copy) == ["verdict partial"]
