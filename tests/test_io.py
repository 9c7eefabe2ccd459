"""Ground-floor file IO (distgprl/io.py): atomic writes and content hashes."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from distgprl import io


def test_atomic_write_leaves_old_file_when_interrupted(tmp_path, monkeypatch):
    """If the final rename fails, the target keeps its old content and no temp file is left."""
    target = tmp_path / "f.txt"
    io.atomic_write_text(target, "old")

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(io.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        io.atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.txt"]


def test_atomic_open_discards_a_failed_block(tmp_path):
    """An exception inside the `atomic_open` block leaves the target untouched and no temp file."""
    target = tmp_path / "f.bin"
    io.atomic_write_bytes(target, b"old")
    with pytest.raises(RuntimeError, match="half-way"):
        with io.atomic_open(target) as handle:
            handle.write(b"partial")
            raise RuntimeError("half-way")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.bin"]


def test_atomic_open_takes_a_streaming_writer(tmp_path):
    """`np.savez` into an `atomic_open` handle (parent folders created) round-trips the arrays."""
    target = tmp_path / "deep" / "a.npz"
    with io.atomic_open(target) as handle:
        np.savez(handle, x=np.arange(5.0))
    with np.load(target) as data:
        np.testing.assert_array_equal(data["x"], np.arange(5.0))


def test_written_files_are_world_readable(tmp_path):
    """Files are created 0644 although `mkstemp` would make them 0600."""
    path = io.atomic_write_text(tmp_path / "r.txt", "x")
    assert path.stat().st_mode & 0o777 == 0o644


def test_atomic_write_json_is_plain_json_dumps(tmp_path):
    """`atomic_write_json` writes exactly `json.dumps(payload, **dumps)`."""
    payload = {"b": [1, 2.5], "a": None}
    path = io.atomic_write_json(tmp_path / "x.json", payload, sort_keys=True)
    assert path.read_text() == json.dumps(payload, sort_keys=True)


def test_config_hash_is_order_independent():
    """Key order does not change a config hash; a value does."""
    assert io.config_hash({"a": 1, "b": 2}) == io.config_hash({"b": 2, "a": 1})
    assert io.config_hash({"a": 1}) != io.config_hash({"a": 2})


def test_config_hash_definition_is_the_one_committed_runs_use():
    """The run identity: first 16 hex digits of SHA-256 over compact, key-sorted JSON."""
    config = {"task": "dcp", "steps": 3, "path": io.__file__}
    blob = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    assert io.config_hash(config) == hashlib.sha256(blob.encode()).hexdigest()[:16]


def test_sha256_helpers_agree(tmp_path):
    """`sha256_hex` hashes a str as its UTF-8 bytes; `file_sha256` hashes a file's bytes."""
    path = tmp_path / "d.txt"
    path.write_bytes("é\n".encode())
    assert io.sha256_hex("é\n") == io.sha256_hex("é\n".encode()) == io.file_sha256(path)
    assert io.file_sha256(path) == hashlib.sha256("é\n".encode()).hexdigest()


def test_remove_partial_writes_takes_only_atomic_open_leftovers(tmp_path):
    """A writer killed inside `atomic_open` leaves ``.<name>.<random>.tmp`` beside the file it
    was replacing: removed (and returned); the file itself, the run lock, other hidden files
    and subfolders' files are left alone."""
    (tmp_path / "progress.csv").write_text("intact")
    leftover = tmp_path / ".progress.csv.meta.json.wsaoftax.tmp"
    leftover.write_text("half")
    keep = [tmp_path / ".lock", tmp_path / ".model.tmp.zip", tmp_path / "notes.tmp"]
    for path in keep:
        path.write_text("")
    (tmp_path / "checkpoints").mkdir()
    nested = tmp_path / "checkpoints" / ".state.pkl.abc.tmp"
    nested.write_text("")
    assert io.remove_partial_writes(tmp_path) == [leftover]
    assert not leftover.exists() and all(p.exists() for p in [*keep, nested])
    assert (tmp_path / "progress.csv").read_text() == "intact"
    assert io.remove_partial_writes(tmp_path) == []
