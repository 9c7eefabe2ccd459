"""One verdict on a run folder, read from the folder alone: `distgprl status`, `sweep`,
`tables` and `curves` all ask `run_state`, so a damaged run gets the same verdict everywhere.

| verdict   | meaning                                                                       |
|-----------|-------------------------------------------------------------------------------|
| `done`    | finished (``done.json``; ``summary.json`` for `demo`) with the current hash   |
| `stale`   | finished with another configuration (a sweep would retrain it)                |
| `damaged` | a result file is not readable as a result of this schema, or one a finished,  |
|           | evaluated run needs is gone (`RunState.file` and `RunState.reason` say which  |
|           | and why); reported everywhere, retrained only when asked                      |
|           | (``sweep --retrain-damaged``)                                                 |
| `running` | a process holds the run folder's lock (``.lock``)                             |
| `failed`  | ``error.json`` from the last attempt, nobody training it now                  |
| `partial` | started, not finished, nobody training it: a sweep resumes it                 |
| `missing` | nothing yet                                                                   |

Damage, checked first for any run folder no process holds locked (a running trainer owns
its folder; its files are written atomically, so it leaves none half-written):

- every ``config.json``, ``done.json`` and ``summary*.json`` present must be a JSON result
  of this schema (`read_json`), a ``summary*.json`` with a ``summary`` object;
- every ``progress.csv`` and ``evaluation*.csv`` present must be a CSV result of this
  schema (`read_csv`), the learning curve with an integer ``step`` on every row;
- a trained run marked finished (``done.json``) and evaluated (``summary.json``) must have
  its per-episode ``evaluation.csv``.

A trained run with ``done.json`` but no evaluation (``train --no-evaluate``) is `done`: it
has nothing damaged, only nothing to tabulate yet.

This module imports neither torch nor pybullet (the reports use it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from distgprl.schema import SchemaVersionError, read_csv, read_json

VERDICTS = ("done", "running", "partial", "failed", "stale", "damaged", "missing")
"""Every verdict `run_state` gives, in the order `distgprl status` counts them."""

RESULT_FILES = ("config.json", "done.json", "progress.csv")
"""Result files checked when present, besides every ``summary*.json`` / ``evaluation*.csv``."""


class DamagedRunError(SchemaVersionError):
    """A report met a damaged run (`RunState`): the message names the file and the reason."""


@dataclass(frozen=True)
class RunState:
    """The verdict on one run folder.

    Attributes:
        verdict: one of `VERDICTS`.
        folder: the run folder ``<root>/<preset>/<task>/<method>/seed<k>``.
        file: `damaged`: the damaged (or missing) file; else None.
        reason: `damaged`: why, one line; `failed`: the recorded error; else empty.
    """

    verdict: str
    folder: Path
    file: Path | None = None
    reason: str = ""

    def describe(self) -> str:
        """``"<file>: <reason>"`` for a damaged run, the reason (if any) otherwise."""
        if self.verdict == "damaged":
            return f"{self.file}: {self.reason}"
        return self.reason

    def error(self) -> DamagedRunError:
        """The error a report raises for this damaged run (exit 2 at the CLI)."""
        return DamagedRunError(
            f"damaged run {self.describe()} (`distgprl status` lists it; "
            "`distgprl sweep --retrain-damaged` retrains it)"
        )


def _reason(error: Exception, path: Path) -> str:
    """The error's message without the leading ``<path>: `` the result readers put there."""
    text = str(error)
    return text.removeprefix(f"{path}: ")


def _check_json(path: Path) -> str:
    """Why ``path`` is not a readable JSON result (empty if it is)."""
    try:
        document = read_json(path)
    except SchemaVersionError as error:
        return _reason(error, path)
    except (OSError, UnicodeDecodeError) as error:
        return f"cannot be read ({type(error).__name__}: {error})"
    if path.name.startswith("summary") and not isinstance(document.get("summary"), dict):
        return "no 'summary' object"
    return ""


def _check_csv(path: Path) -> str:
    """Why ``path`` is not a readable CSV result (empty if it is)."""
    try:
        _, rows = read_csv(path)
    except SchemaVersionError as error:
        return _reason(error, path)
    except (OSError, UnicodeDecodeError) as error:
        return f"cannot be read ({type(error).__name__}: {error})"
    if path.name == "progress.csv":
        for number, row in enumerate(rows, start=1):
            try:
                int(row["step"])
            except (KeyError, TypeError, ValueError):
                return f"row {number} has no integer 'step' ({row.get('step')!r})"
    return ""


def _signature(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """(name, mtime ns, size) of the folder's files: a changed file changes it."""
    out = []
    for path in folder.iterdir():
        try:
            stat = path.stat()
        except FileNotFoundError:  # removed while listing
            continue
        if path.is_file():
            out.append((path.name, stat.st_mtime_ns, stat.st_size))
    return tuple(sorted(out))


@lru_cache(maxsize=4096)
def _damage_of(
    folder: Path, trainable: bool, signature: tuple[tuple[str, int, int], ...]
) -> tuple[str, str]:
    """(file name, reason) of the folder's first damaged file, or ("", "")."""
    names = {name for name, _, _ in signature}
    for name in sorted(names):
        path = folder / name
        if name in RESULT_FILES or name.startswith(("summary", "evaluation")):
            if name.endswith(".json"):
                reason = _check_json(path)
            elif name.endswith(".csv"):
                reason = _check_csv(path)
            else:
                continue
            if reason:
                return name, reason
    if trainable and {"done.json", "summary.json"} <= names and "evaluation.csv" not in names:
        return "evaluation.csv", "missing, although done.json and summary.json mark the run " + (
            "finished and evaluated"
        )
    return "", ""


def damage(folder: Path, trainable: bool) -> tuple[Path, str] | None:
    """(file, reason) of the run folder's first damaged result file, or None (module
    docstring). Cached on the folder's file names, times and sizes."""
    folder = Path(folder)
    if not folder.is_dir():
        return None
    name, reason = _damage_of(folder, trainable, _signature(folder))
    return (folder / name, reason) if name else None


def run_state(folder: str | Path, trainable: bool, current_hash: str | None) -> RunState:
    """The verdict on a run folder (never writes).

    Args:
        folder: the run folder.
        trainable: whether the run's method trains (its finish marker is ``done.json``;
            the untrained `demo` reference's is ``summary.json``).
        current_hash: the config hash the code resolves for the run now, or None if it
            cannot be resolved (a preset not in this checkout): then a finished run is
            `done` whatever hash it records.
    """
    from distgprl.io import is_locked

    folder = Path(folder)
    if not folder.is_dir():
        return RunState("missing", folder)
    if is_locked(folder):  # its trainer owns the folder now; judged once it lets go
        return RunState("running", folder)
    damaged = damage(folder, trainable)
    if damaged is not None:
        return RunState("damaged", folder, damaged[0], damaged[1])
    marker = folder / ("done.json" if trainable else "summary.json")
    if marker.exists():
        recorded = read_json(marker)["meta"].get("config_hash")
        if current_hash is None or recorded == current_hash:
            return RunState("done", folder)
        return RunState("stale", folder, reason=f"config {recorded}, the code now {current_hash}")
    if (folder / "error.json").exists():
        try:
            error = str(read_json(folder / "error.json").get("error", ""))
        except Exception:  # noqa: BLE001 - a failure record is not a result; say so
            error = "unreadable error.json"
        return RunState("failed", folder, reason=error)
    if any((folder / name).exists() for name in ("config.json", "progress.csv", "summary.json")):
        return RunState("partial", folder)
    return RunState("missing", folder)


def job_state(root: str | Path, preset: str, task: str, method: str, seed: int) -> RunState:
    """`run_state` of ``<root>/<preset>/<task>/<method>/seed<seed>`` against the config hash
    the code resolves for it now (names must be valid: `resolve_run`)."""
    from distgprl.identity import resolve_run
    from distgprl.methods import get_method
    from distgprl.schema import run_dir

    run = resolve_run(task, method, seed, preset)
    folder = run_dir(root, preset, task, method, seed)
    return run_state(folder, get_method(method).trainable, run.hash)
