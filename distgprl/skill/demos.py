"""Demonstration files: a documented CSV format, a validating loader and a writer.

Format (one header line, then one row per sample)::

    t,x,y,z,rx,ry,rz
    0.000,0.4000,-0.2000,0.3000,3.1416,0.0000,0.0000
    ...

- ``t``: time in seconds, strictly increasing.
- ``x, y, z``: tool-centre-point position in the robot base frame, metres.
- ``rx, ry, rz``: tool orientation as a rotation vector (axis * angle, UR convention), radians.

Every cell must be a finite number. Extra columns are rejected so that a file
in another convention is not silently misread.

A demonstration *set* is a folder of such files with a ``tcs.json`` index::

    {"task": "dcp", "seed": 3141592, "files": ["demo_00.csv", ...],
     "tcs": [{"object_offset": [dx, dy], "obstacle_offset": [dx, dy]}, ...]}

- ``task``: the task the demonstrations were made for.
- ``files``: the demonstration CSVs in the folder, one per TC, distinct.
- ``tcs``: the task configuration each demonstration was made (and succeeded) for, in the
  same order; offsets in metres.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError
from distgprl.io import atomic_write_text, sha256_hex

COLUMNS: tuple[str, ...] = ("t", "x", "y", "z", "rx", "ry", "rz")

SET_INDEX = "tcs.json"
"""The file of a demonstration set that lists its demonstrations and their TCs."""


@dataclass(frozen=True)
class Demonstration:
    """A time-stamped 6-D pose trajectory.

    Attributes:
        times: shape (n,), seconds, strictly increasing.
        poses: shape (n, 6), metres and radians (x, y, z, rx, ry, rz).
        name: a short name (file stem or task name).
        sha256: hex digest of the source file bytes ("" if built in memory).
    """

    times: np.ndarray
    poses: np.ndarray
    name: str = "demo"
    sha256: str = ""

    @property
    def duration(self) -> float:
        """Total duration in seconds."""
        return float(self.times[-1] - self.times[0])

    @property
    def normalised_times(self) -> np.ndarray:
        """Times mapped to tau in [0, 1], shape (n,)."""
        tau: np.ndarray = (self.times - self.times[0]) / self.duration
        return tau


def load_demonstration(path: str | Path, min_rows: int = 2) -> Demonstration:
    """Load and validate a demonstration CSV.

    Args:
        path: the CSV file.
        min_rows: the fewest data rows accepted (e.g. the number of via-points).

    Raises:
        UserInputError: with a one-line message naming the file, the line and the problem.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise UserInputError(f"{path}: cannot read demonstration ({exc.strerror})") from exc
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserInputError(f"{path}: not a UTF-8 text file") from exc
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise UserInputError(f"{path}:1: empty file, expected header {','.join(COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise UserInputError(
            f"{path}:1: missing column(s) {','.join(missing)}; expected header {','.join(COLUMNS)}"
        )
    extra = [h for h in header if h not in COLUMNS]
    if extra:
        raise UserInputError(
            f"{path}:1: unexpected column(s) {','.join(extra)}; expected {','.join(COLUMNS)}"
        )
    order = [header.index(c) for c in COLUMNS]
    values: list[list[float]] = []
    for line_no, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise UserInputError(
                f"{path}:{line_no}: expected {len(header)} cells, found {len(row)}"
            )
        parsed = []
        for col in order:
            cell = row[col].strip()
            try:
                value = float(cell)
            except ValueError:
                raise UserInputError(
                    f"{path}:{line_no}: column '{header[col]}' is not a number: {cell!r}"
                ) from None
            if not np.isfinite(value):
                raise UserInputError(
                    f"{path}:{line_no}: column '{header[col]}' is not finite: {cell!r}"
                )
            parsed.append(value)
        if values and parsed[0] <= values[-1][0]:
            raise UserInputError(
                f"{path}:{line_no}: time {parsed[0]:g} is not greater than the previous "
                f"time {values[-1][0]:g} (time must increase strictly)"
            )
        values.append(parsed)
    if len(values) < max(min_rows, 2):
        raise UserInputError(f"{path}: {len(values)} data row(s), need at least {max(min_rows, 2)}")
    data = np.asarray(values, dtype=float)
    return Demonstration(
        times=data[:, 0].copy(),
        poses=data[:, 1:].copy(),
        name=path.stem,
        sha256=sha256_hex(raw),
    )


def save_demonstration(path: str | Path, times: np.ndarray, poses: np.ndarray) -> None:
    """Write a demonstration CSV in the documented format (atomically).

    Args:
        times: shape (n,), seconds, strictly increasing.
        poses: shape (n, 6), metres and radians.
    """
    times = np.asarray(times, dtype=float)
    poses = np.asarray(poses, dtype=float)
    if times.ndim != 1 or poses.shape != (times.shape[0], 6):
        raise ValueError(f"expected times (n,) and poses (n, 6), got {times.shape}, {poses.shape}")
    if np.any(np.diff(times) <= 0):
        raise ValueError("times must increase strictly")
    lines = [",".join(COLUMNS)]
    for t, pose in zip(times, poses, strict=True):
        lines.append(",".join(f"{v:.6f}" for v in (t, *pose)))
    atomic_write_text(path, "\n".join(lines) + "\n")


@dataclass(frozen=True)
class DemonstrationSetEntry:
    """One demonstration of a set and the TC it was made for.

    Attributes:
        path: the demonstration CSV.
        demonstration: its contents.
        tc: its ``tcs.json`` entry (``object_offset`` and ``obstacle_offset``, 2 numbers each, m).
    """

    path: Path
    demonstration: Demonstration
    tc: dict[str, list[float]]


def load_demonstration_set(
    folder: str | Path, count: int, task: str | None = None
) -> list[DemonstrationSetEntry]:
    """Load and validate a demonstration set: exactly ``count`` distinct demonstrations listed
    in ``folder/tcs.json``, each a valid CSV with a TC of two finite offsets.

    Whether each demonstration succeeds for its TC is the simulator's to say
    (`distgprl.envs.windowed_residual_env.expert_demonstration_set` executes them).

    Args:
        folder: the set's folder.
        count: how many demonstrations the set must hold.
        task: if given, the task ``tcs.json`` must name.

    Raises:
        UserInputError: one line naming the folder, ``tcs.json`` or the file at fault.
    """
    folder = Path(folder)
    index_path = folder / SET_INDEX
    index = _read_set_index(index_path)
    files, tcs = index.get("files"), index.get("tcs")
    if not isinstance(files, list) or not isinstance(tcs, list):
        raise UserInputError(f"{index_path}: needs a 'files' list and a 'tcs' list")
    if len(files) != len(tcs):
        raise UserInputError(f"{index_path}: {len(files)} files but {len(tcs)} TCs")
    if len(files) != count:
        raise UserInputError(
            f"{folder}: {len(files)} demonstrations listed in {SET_INDEX}, need exactly {count}"
        )
    if len(set(map(str, files))) != len(files):
        raise UserInputError(f"{index_path}: a demonstration file is listed twice")
    if task is not None and index.get("task") != task:
        raise UserInputError(f"{index_path}: made for task {index.get('task')!r}, not {task!r}")
    entries = []
    for k, (name, tc) in enumerate(zip(files, tcs, strict=True)):
        checked = _checked_tc(tc, index_path, k)
        path = folder / str(name)
        entries.append(DemonstrationSetEntry(path, load_demonstration(path), checked))
    return entries


def _read_set_index(path: Path) -> dict[str, Any]:
    """The parsed ``tcs.json`` of a set (a JSON object), or a `UserInputError` naming it."""
    try:
        index = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UserInputError(f"{path}: cannot read the demonstration set ({exc.strerror})") from exc
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserInputError(f"{path}: not a JSON file ({exc})") from exc
    if not isinstance(index, dict):
        raise UserInputError(f"{path}: expected a JSON object")
    return index


def _checked_tc(tc: object, path: Path, k: int) -> dict[str, list[float]]:
    """The ``k``-th TC of ``path`` with two finite numbers per offset, else a `UserInputError`."""
    keys = ("object_offset", "obstacle_offset")
    try:
        checked = {key: [float(v) for v in tc[key]] for key in keys}  # type: ignore[index]
    except (KeyError, TypeError, ValueError):
        checked = {}
    if not checked or any(len(v) != 2 or not np.all(np.isfinite(v)) for v in checked.values()):
        raise UserInputError(f"{path}: TC {k} needs {' and '.join(keys)}, two finite numbers each")
    return checked
