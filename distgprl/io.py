"""Ground-floor file IO: atomic writes and content hashes.

Every file the package writes (results, caches, calibration files, generated URDFs and marker
textures) goes through :func:`atomic_open` or one of its wrappers: the bytes are written to a
temporary file in the target's folder, flushed and fsynced, then renamed over the target, so a
reader (or a killed writer) sees either the previous file or the complete new one, never a
partial file. Files are created with mode 0644 (shared, like any file the user writes).

The hashes identify content: :func:`config_hash` a JSON-serialisable configuration (the run
identity of every committed result, so its definition must never change), :func:`file_sha256`
and :func:`sha256_hex` bytes.

This module imports only the standard library, so every layer may use it.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = [
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "config_hash",
    "file_sha256",
    "sha256_hex",
]


@contextmanager
def atomic_open(path: str | Path) -> Iterator[IO[bytes]]:
    """A binary handle whose content replaces ``path`` atomically when the block exits.

    The handle writes to a temporary file beside ``path`` (parent folders are created); on a
    clean exit it is flushed, fsynced and renamed over ``path``; on an exception the temporary
    file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o644)  # mkstemp creates 0600; result files are meant to be shared
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def remove_partial_writes(folder: str | Path) -> list[Path]:
    """Remove the temporary files `atomic_open` left in ``folder`` (not its subfolders) when
    a writer died between creating one and renaming it (kill -9, a lost node); returns them.

    Only for a folder no other process is writing: the caller holds its lock (a run folder
    under `distgprl.experiments.run_control.run_lock`). The files it replaces are intact.
    """
    leftovers = sorted(
        path
        for path in Path(folder).glob(".*.tmp")
        if path.is_file() and path.name.count(".") >= 3  # ".<name>.<random>.tmp"
    )
    for path in leftovers:
        path.unlink(missing_ok=True)
    return leftovers


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder + rename)."""
    with atomic_open(path) as handle:
        handle.write(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 text atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | Path, payload: Any, **dumps: Any) -> Path:
    """Write ``json.dumps(payload, **dumps)`` atomically (no trailing newline is added)."""
    return atomic_write_text(path, json.dumps(payload, **dumps))


def sha256_hex(data: bytes | str) -> str:
    """Hex SHA-256 of ``data`` (a ``str`` is hashed as its UTF-8 bytes)."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    return hashlib.sha256(data).hexdigest()


def config_hash(config: Mapping[str, Any]) -> str:
    """A short stable hash of a JSON-serialisable configuration: the first 16 hex digits of the
    SHA-256 of its canonical JSON (sorted keys, no spaces, ``str`` for other values)."""
    blob = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return sha256_hex(blob)[:16]


def file_sha256(path: str | Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes, read ``chunk_bytes`` at a time (a replay buffer of
    gigabytes is never held in memory whole)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


def is_locked(folder: str | Path) -> bool:
    """True if a process holds ``folder``'s run lock (is training it) right now."""
    path = Path(folder) / ".lock"
    try:
        descriptor = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(descriptor)  # closing releases the probe's lock if it got one
    return False
