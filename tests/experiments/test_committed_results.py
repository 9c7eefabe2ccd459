"""Every committed result file under ``results/`` (except ``results/archive/``) names, in its
``meta.git_commit``, a commit of this repository's history: whoever reads a result can
check out the code that produced it. ``+dirty`` results name their base commit."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections import defaultdict
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[2]


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=REPOSITORY, capture_output=True, text=True)


def _committed_result_files() -> list[str]:
    """Tracked ``.json`` / ``.csv`` files under ``results/``, not under ``results/archive/``."""
    listed = _git("ls-files", "-z", "--", "results").stdout.split("\0")
    return sorted(
        name
        for name in listed
        if name.endswith((".json", ".csv")) and not name.startswith("results/archive/")
    )


def _recorded_commit(path: Path) -> str | None:
    """``meta.git_commit`` of a versioned JSON or CSV result (None if it has no meta block)."""
    try:
        if path.suffix == ".json":
            document = json.loads(path.read_text())
            meta = document.get("meta") if isinstance(document, dict) else None
        else:
            with open(path) as handle:
                first = handle.readline()
            meta = (
                json.loads(first.removeprefix("# meta: ")) if first.startswith("# meta: ") else None
            )
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return meta.get("git_commit") if isinstance(meta, dict) else None


@pytest.fixture(scope="module")
def history():
    """Skip unless this is a full git checkout (a shallow clone lacks old commits)."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed: cannot check the commits results name")
    if _git("rev-parse", "--is-inside-work-tree").stdout.strip() != "true":
        pytest.skip(f"{REPOSITORY} is not a git checkout: cannot check the commits results name")
    if _git("rev-parse", "--is-shallow-repository").stdout.strip() == "true":
        pytest.skip("shallow clone: older commits are absent by design (fetch with --unshallow)")


def test_every_committed_result_names_a_commit_of_this_history(history):
    files = _committed_result_files()
    assert files, "no committed result files found under results/"
    by_commit: dict[str, list[str]] = defaultdict(list)
    for name in files:
        commit = _recorded_commit(REPOSITORY / name)
        if commit is not None:  # result files without a meta block are not versioned results
            by_commit[commit.removesuffix("+dirty")].append(name)
    assert by_commit, "no committed result file records a git_commit"
    unknown = {
        commit: names
        for commit, names in by_commit.items()
        if _git("cat-file", "-e", f"{commit}^{{commit}}").returncode != 0
    }
    listing = [
        f"{commit} ({len(names)} files): "
        + ", ".join(sorted({str(Path(name).parent) for name in names}))
        for commit, names in sorted(unknown.items())
    ]
    assert not unknown, "results naming a commit not in this history:\n" + "\n".join(listing)
