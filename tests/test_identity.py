"""Run identity (`distgprl.identity`): the config hash covers the committed skill file, so a
refitted skill (`distgprl fit --write`) makes every run of that task stale."""

from __future__ import annotations

import shutil

from distgprl import identity
from distgprl.data import DATA_DIR


def test_the_config_hash_changes_with_the_committed_skill_file(tmp_path, monkeypatch):
    data = tmp_path / "data"
    shutil.copytree(DATA_DIR / "skills", data / "skills")
    monkeypatch.setattr(identity, "DATA_DIR", data)
    before = identity.resolve_run("dcp", "dist-gprl", 0, "paper").hash
    other = identity.resolve_run("dbm", "dist-gprl", 0, "paper").hash
    path = data / "skills" / "dcp.json"
    path.write_text(path.read_text().replace("\n", "\n ", 1))  # same numbers, other bytes
    assert identity.resolve_run("dcp", "dist-gprl", 0, "paper").hash != before
    assert identity.resolve_run("dbm", "dist-gprl", 0, "paper").hash == other


def test_a_task_without_a_committed_skill_hashes_without_one(tmp_path, monkeypatch):
    monkeypatch.setattr(identity, "DATA_DIR", tmp_path)
    assert identity.committed_skill_digest("dcp") is None
    assert "skill_sha256" not in identity.resolve_run("dcp", "demo", 0, "paper").to_dict()
