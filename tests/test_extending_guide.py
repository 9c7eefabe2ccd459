"""docs/guides/extending.md is followed as written: its code blocks, applied to a copy of the
package, add the example task and method, and its commands (at a small size) demonstrate,
fit, measure, train and evaluate them. A step that goes stale fails here."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import distgprl

REPOSITORY = Path(__file__).resolve().parents[1]
GUIDE = REPOSITORY / "docs" / "guides" / "extending.md"
PACKAGE = Path(distgprl.__file__).resolve().parent

TASK, METHOD = "dcpslow", "gprl-d-nocov"

BLOCK = re.compile(r'^```(\w+) title="([^"]+)"\n(.*?)^```', re.MULTILINE | re.DOTALL)
INSERT = re.compile(r"# add inside \w+, before: (.+)")
REPLACE = "# change the lines that begin like these"

SMALL = {
    # the guide's commands at a test's size (the guide's own sizes are the presets')
    "distgprl.sim.difficulty": ["--episodes", "20"],
    "train": ["--steps", "90", "--no-evaluate"],
}


def guide_blocks() -> list[tuple[str, str, str]]:
    """(language, title, body) of every titled code block of the guide, in order."""
    return [(m[1], m[2], m[3]) for m in BLOCK.finditer(GUIDE.read_text())]


def apply_block(root: Path, title: str, body: str) -> None:
    """Apply one code block to the package copy under ``root`` as its first line says: insert
    it before an anchor line, replace the lines that begin like its lines, or (no such line)
    create the file it is titled with."""
    path = root / title
    first, _, rest = body.partition("\n")
    insert = INSERT.fullmatch(first)
    if insert:
        lines = path.read_text().splitlines(keepends=True)
        hits = [i for i, line in enumerate(lines) if line.strip().startswith(insert[1])]
        assert len(hits) == 1, f"{title}: anchor {insert[1]!r} found {len(hits)} times"
        indent = lines[hits[0]][: len(lines[hits[0]]) - len(lines[hits[0]].lstrip())]
        block = [indent + line if line.strip() else line for line in rest.splitlines(True)]
        lines[hits[0] : hits[0]] = block
        path.write_text("".join(lines))
    elif first == REPLACE:
        text = path.read_text()
        for line in rest.splitlines():
            head = re.match(r"(.*?(?: = | import ))", line)
            assert head, f"{title}: {line!r} is neither an assignment nor an import"
            old = [old for old in text.splitlines() if old.startswith(head[1])]
            assert len(old) == 1, f"{title}: {head[1]!r} begins {len(old)} lines"
            text = text.replace(old[0] + "\n", line + "\n")
        path.write_text(text)
    else:
        assert not path.exists(), f"{title}: a new file's block, but the file exists"
        path.write_text(body)


def command_argv(line: str) -> tuple[str, list[str]]:
    """A guide command as (its name in `SMALL`, argv with this interpreter)."""
    words = shlex.split(line)
    if words[:2] == ["python", "-m"]:
        return words[2], [sys.executable, "-m", *words[2:]]
    assert words[0] == "distgprl", f"not a distgprl command: {line!r}"
    return words[1], [sys.executable, "-m", "distgprl", *words[1:]]


def record_demo_outcome(root: Path, printed: str) -> None:
    """Step 4 of the guide: the difficulty command's figures as the task's entry of
    ``demo_outcomes.json`` (success without collision = 1 - fail_or_collide_rate)."""
    line = next(line for line in printed.splitlines() if line.startswith(f"{TASK} "))
    figures = {key: float(value) for key, value in re.findall(r"(\w+)=([-\d.]+)", line)}
    path = root / "distgprl" / "data" / "demo_outcomes.json"
    outcomes = json.loads(path.read_text())
    outcomes["tasks"][TASK] = {
        "episodes": int(figures["episodes"]),
        "progress": figures["progress"],
        "success_rate": 1.0 - figures["fail_or_collide_rate"],
        "collision_rate": figures["collision_rate"],
    }
    path.write_text(json.dumps(outcomes, indent=1) + "\n")


def test_the_guide_has_the_blocks_this_test_follows():
    """The test is not vacuous: the guide adds a module, edits registries, runs commands."""
    titles = [title for _, title, _ in guide_blocks()]
    assert f"distgprl/sim/tasks/{TASK}.py" in titles
    assert titles.count("distgprl/methods.py") == 2
    assert {"distgprl/data/__init__.py", "distgprl/sim/tasks/__init__.py", "shell"} <= set(titles)


def test_following_the_guide_adds_a_task_and_a_method_that_train_and_evaluate(tmp_path):
    root = tmp_path / "package"
    shutil.copytree(PACKAGE, root / "distgprl", ignore=shutil.ignore_patterns("__pycache__"))
    environment = {
        **os.environ,
        "PYTHONPATH": str(root),
        "MPLBACKEND": "Agg",
        "DISTGPRL_CACHE_DIR": str(tmp_path / "cache"),
    }
    ran = []
    for language, title, body in guide_blocks():
        if title != "shell":
            assert language == "python", title
            apply_block(root, title, body)
            continue
        for line in body.strip().splitlines():
            name, argv = command_argv(line)
            if name in ("train", "evaluate"):  # the guide's --root, in the temporary folder
                argv += ["--root", str(tmp_path / "runs")]
            result = subprocess.run(
                argv + SMALL.get(name, []),
                cwd=tmp_path,
                env=environment,
                capture_output=True,
                text=True,
                timeout=900,
            )
            assert result.returncode == 0, f"{line}:\n{result.stdout}\n{result.stderr}"
            if name == "distgprl.sim.difficulty":
                record_demo_outcome(root, result.stdout)
            ran.append(name)
    assert ran == ["distgprl.sim.experts", "fit", "distgprl.sim.difficulty", "train", "evaluate"]
    data = root / "distgprl" / "data"
    assert (data / "demos" / f"{TASK}.csv").is_file()
    assert len(list((data / "demos" / f"{TASK}_varied").glob("demo_*.csv"))) == 20
    assert json.loads((data / "skills" / f"{TASK}.json").read_text())["task"] == TASK
    run = tmp_path / "runs" / "ci" / TASK / METHOD / "seed0"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["meta"]["task"] == TASK and summary["meta"]["method"] == METHOD
    assert summary["summary"]["episodes"] > 0  # the ci preset's evaluation TCs
    assert 0.0 <= summary["summary"]["success_rate"] <= 1.0
    # the new task's gymnasium ids come with `import distgprl`; the method stays out of Table I
    check = subprocess.run(
        [
            sys.executable,
            "-c",
            "import distgprl, gymnasium; from distgprl.methods import TABLE_ORDER; "
            "from distgprl.config_types import ENVIRONMENT_VERSION as N; "
            f"print(gymnasium.spec(f'DistGPRL-{TASK.upper()}-v{{N}}').kwargs, "
            f"{METHOD!r} in TABLE_ORDER)",
        ],
        cwd=tmp_path,  # not the repository: `-c` puts the working directory first on sys.path
        env=environment,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert check.returncode == 0, check.stderr
    assert check.stdout.split() == ["{'task':", f"'{TASK}'}}", "False"]


@pytest.mark.parametrize("first", [REPLACE, "# add inside METHODS, before: MethodSpec("])
def test_an_edit_whose_anchor_is_gone_fails_loudly(tmp_path, first):
    """The block applier does not skip an edit it cannot place (the guide would be stale)."""
    (tmp_path / "module.py").write_text("A = 1\n")
    with pytest.raises(AssertionError):
        apply_block(tmp_path, "module.py", f"{first}\nB: int = 2\n")
