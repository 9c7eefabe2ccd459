"""Which run folders the tables, paired analyses and curves may use.

A run counts when it has the result file a report reads — ``summary.json`` (evaluated) for the
tables and paired analyses, ``done.json`` (trained) for the learning curves — and the config
hash recorded there is the one the code resolves for it now: a run of an older configuration
(say, before a fix to a part of the method, which changes the hash of the methods using it)
is left out, and listed, instead of being averaged with the current ones. `distgprl status`
calls such runs "stale". A damaged run (the `distgprl.runstate` verdict
``damaged``: a result file of an unknown schema version or not a result at all, or the
evaluation of a finished run gone) is an error naming the file and the reason
(:class:`~distgprl.runstate.DamagedRunError`, exit 2 at the CLI), in the tables
and the curves alike, never a run quietly left out.

So a report is a function of the result files and, for this checkout's presets, of the
configuration the code resolves for them (presets and method revisions): a change to a
preset or to a part of the method changes which runs count, not their figures.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.methods import METHODS
from distgprl.runstate import run_state
from distgprl.schema import read_json


@dataclass(frozen=True)
class RunSelection:
    """Run folders (``<root>/<preset>/<task>/<method>/seed<k>``) that count, and why others
    do not.

    Attributes:
        current: the runs (with the marker file) of the current configuration.
        excluded: one line per left-out run: its ``task/method/seed<k>`` and the reason.
        checked: False if the preset is not one of this checkout's (``experiments/``), so
            the config hashes could not be checked (only "finished" was).
    """

    current: frozenset[Path]
    excluded: tuple[str, ...]
    checked: bool

    def note(self) -> str:
        """A sentence for the tables: what was left out (empty if nothing)."""
        parts = []
        if self.excluded:
            parts.append(f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded))
        if not self.checked:
            parts.append("Config hashes not checked: the preset is not in experiments/")
        return ". ".join(parts)


@cache
def known_preset(preset: str) -> bool:
    """Whether ``preset`` is one of this checkout's (so its runs' hashes can be resolved)."""
    from distgprl.config import load_config

    try:
        load_config(preset)
    except UserInputError:
        return False
    return True


@cache
def current_hash(task: str, method: str, seed: int, preset: str) -> str:
    """The config hash the code resolves for a run (fixed while the process runs; the reports
    ask for the same runs once per table, figure and method)."""
    from distgprl.identity import resolve_run

    return resolve_run(task, method, seed, preset).hash


def select_runs(root: str | Path, preset: str, marker: str = "summary.json") -> RunSelection:
    """The run folders under ``<root>/<preset>`` holding ``marker`` (``summary.json`` or
    ``done.json``; the untrained `demo` reference always by its ``summary.json``) of the
    current configuration (module docstring)."""
    base = Path(root) / preset
    folders = sorted(p for p in base.glob("*/*/seed*") if p.is_dir())
    checked = known_preset(preset)
    current, excluded = set(), []
    for folder in folders:
        task, method = folder.parent.parent.name, folder.parent.name
        if method not in METHODS:
            continue
        name = f"{task}/{method}/{folder.name}"
        trainable = METHODS[method].trainable
        hash_now = None
        if checked:
            hash_now = current_hash(task, method, int(folder.name.removeprefix("seed")), preset)
        # A damaged run stops the report, never a run silently left out (exit 2).
        state = run_state(folder, trainable, hash_now)
        if state.verdict == "damaged":
            raise state.error()
        path = folder / (marker if trainable else "summary.json")
        if not path.exists():
            continue
        recorded = read_json(path)["meta"].get("config_hash")
        if checked:
            if recorded != hash_now:
                excluded.append(f"{name} (configuration changed since; `distgprl status`: stale)")
                continue
        current.add(folder)
    return RunSelection(frozenset(current), tuple(excluded), checked)
