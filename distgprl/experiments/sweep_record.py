"""What the sweeps into a results root were asked for, so that `distgprl status` without
``--methods``, ``--tasks`` or ``--seeds`` reports those runs (after ``sweep --seeds 0``, the
seed-0 runs: "18/18 done", not "18/74 done" for seeds nobody asked for).

Each sweep adds its request (methods, tasks, seeds; None: the preset's defaults) to
``<root>/<preset>/.sweeps.json`` (`SWEEPS_FILE`, git-ignored) before it trains; the runs
asked for are the union of every recorded request's (`requested_jobs`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from distgprl.experiments.jobs import Job
from distgprl.io import atomic_write_text

SWEEPS_FILE = ".sweeps.json"
"""The file, in ``<root>/<preset>/``, that lists the requests of the sweeps into it."""


def sweeps_file(root: str | Path, preset: str) -> Path:
    """``<root>/<preset>/.sweeps.json``."""
    return Path(root) / preset / SWEEPS_FILE


def recorded_requests(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """The requests recorded for ``preset`` under ``root``, oldest first (empty if none, or
    if the file is not a list of requests: it is a convenience, not a result)."""
    try:
        requests = json.loads(sweeps_file(root, preset).read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(requests, list):
        return []
    return [r for r in requests if isinstance(r, dict)]


def record_request(
    root: str | Path,
    preset: str,
    methods: Sequence[str] | None,
    tasks: Sequence[str] | None,
    seeds: Sequence[int] | None,
) -> Path:
    """Add one sweep's request (None: the preset's default) to ``.sweeps.json`` (a request
    recorded already is not added twice); returns the file."""
    request = {
        "methods": list(methods) if methods else None,
        "tasks": list(tasks) if tasks else None,
        "seeds": [int(seed) for seed in seeds] if seeds is not None else None,
    }
    requests = recorded_requests(root, preset)
    if request not in requests:
        requests.append(request)
    path = sweeps_file(root, preset)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, json.dumps(requests, indent=1) + "\n")


def requested_jobs(root: str | Path, preset: str) -> list[Job] | None:
    """The union of the jobs every recorded request plans, request by request in the order
    they were recorded (None: no sweep was recorded; a request this checkout cannot plan
    any more is left out)."""
    from distgprl.errors import UserInputError
    from distgprl.experiments.sweep import plan_jobs

    asked: dict[tuple[str, str, str, int], Job] = {}
    for request in recorded_requests(root, preset):
        try:
            jobs = plan_jobs(preset, request["methods"], request["tasks"], request["seeds"], root)
        except (UserInputError, KeyError, TypeError):
            continue
        for job in jobs:
            asked.setdefault((job.preset, job.task, job.method, job.seed), job)
    return list(asked.values()) or None
