"""Versioned, atomic result files (atomic writes and hashes: :mod:`distgprl.io`).

Every result file the project writes carries a ``meta`` block (schema version, package
version, git commit, UTC time, library versions, and whatever the caller adds such as
the config hash and seed) and is written atomically: to a temporary file in the same
folder, flushed and fsynced, then renamed over the target. A reader that finds an
unknown schema version raises :class:`SchemaVersionError` instead of guessing.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

from distgprl import __version__
from distgprl.errors import UserInputError
from distgprl.io import atomic_write_bytes, atomic_write_text, config_hash, file_sha256

# Re-exported for the callers that import them from here (their home is distgprl.io).
__all__ = [
    "SCHEMA_VERSION",
    "SOURCE_PATHS",
    "SchemaVersionError",
    "atomic_write_bytes",
    "atomic_write_text",
    "config_hash",
    "file_sha256",
    "git_commit",
    "library_versions",
    "read_csv",
    "read_json",
    "result_meta",
    "source_commit",
    "write_csv",
    "write_json",
]

SCHEMA_VERSION = 1
_LIBRARIES = ("numpy", "scipy", "torch", "pybullet", "stable_baselines3", "gymnasium")


class SchemaVersionError(UserInputError, ValueError):
    """A result file was written with a schema version this code cannot read."""


SOURCE_PATHS = ("distgprl", "pyproject.toml", "constraints.txt")
"""What `source_commit` checks for local changes (relative to the repository root)."""


@lru_cache(maxsize=1)
def git_commit() -> str:
    """`source_commit` of this package's repository (once per process)."""
    return source_commit(Path(__file__).resolve().parents[2])


def source_commit(root: str | Path) -> str:
    """The commit checked out at ``root``, with ``+dirty`` if the package source or its
    dependency pins have local changes (result files and other untracked files do not
    count: re-evaluating a committed run must not mark its own files dirty); ``unknown``
    outside a git work tree."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *SOURCE_PATHS],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("+dirty" if dirty else "")


@lru_cache(maxsize=1)
def library_versions() -> dict[str, str]:
    """Installed versions of the libraries that determine results."""
    out = {}
    for name in _LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def result_meta(**extra: Any) -> dict[str, Any]:
    """The versioning block stored in every result file."""
    return {
        "schema_version": SCHEMA_VERSION,
        "package_version": __version__,
        "git_commit": git_commit(),
        "utc_time": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "libraries": library_versions(),
        **extra,
    }


def write_json(path: str | Path, payload: Mapping[str, Any], **meta: Any) -> Path:
    """Write a versioned JSON result: ``{"meta": result_meta(**meta), **payload}``."""
    document = {"meta": result_meta(**meta), **payload}
    return atomic_write_text(path, json.dumps(document, indent=2, sort_keys=False) + "\n")


def read_json(path: str | Path) -> dict[str, Any]:
    """Read a versioned JSON result, checking its schema version."""
    path = Path(path)
    try:
        document = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SchemaVersionError(
            f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})"
        ) from None
    meta = document.get("meta") if isinstance(document, dict) else None
    if not isinstance(meta, dict):
        raise SchemaVersionError(f"{path}: no 'meta' object; not a distgprl result")
    version = meta.get("schema_version")
    if version != SCHEMA_VERSION:
        raise SchemaVersionError(
            f"{path}: schema_version {version!r} is not supported (this is schema "
            f"{SCHEMA_VERSION}, distgprl {__version__}); regenerate the file"
        )
    return document


def write_csv(
    path: str | Path,
    rows: Iterable[Mapping[str, Any]],
    fieldnames: Sequence[str],
    **meta: Any,
) -> Path:
    """Write a versioned CSV: one ``# meta: {json}`` comment line, a header, then rows."""
    buffer = io.StringIO()
    buffer.write("# meta: " + json.dumps(result_meta(**meta), sort_keys=True) + "\n")
    writer = csv.DictWriter(buffer, fieldnames=list(fieldnames), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row[k] for k in fieldnames})
    return atomic_write_text(path, buffer.getvalue())


def read_csv(path: str | Path) -> tuple[dict[str, Any], list[dict[str, str]]]:
    """Read a versioned CSV written by :func:`write_csv`: returns (meta, rows)."""
    path = Path(path)
    lines = path.read_text().splitlines()
    if not lines or not lines[0].startswith("# meta: "):
        raise SchemaVersionError(f"{path}: missing '# meta:' header line; not a distgprl result")
    try:
        meta = json.loads(lines[0][len("# meta: ") :])
    except json.JSONDecodeError as exc:
        raise SchemaVersionError(
            f"{path}: '# meta:' line is not valid JSON ({exc.msg}); not a distgprl result"
        ) from None
    if not isinstance(meta, dict):
        raise SchemaVersionError(f"{path}: '# meta:' line is not an object; not a distgprl result")
    if meta.get("schema_version") != SCHEMA_VERSION:
        raise SchemaVersionError(
            f"{path}: schema_version {meta.get('schema_version')!r} is not supported "
            f"(this is schema {SCHEMA_VERSION}); regenerate the file"
        )
    rows = list(csv.DictReader(lines[1:]))
    return meta, rows
