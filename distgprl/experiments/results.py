"""Versioned, atomic result files: re-exported from their homes for existing callers.

The versioned JSON/CSV format (``meta`` block, schema version) lives in :mod:`distgprl.schema`,
atomic writes and hashes in :mod:`distgprl.io`; new code imports from those.
"""

from __future__ import annotations

from distgprl.io import atomic_write_bytes, atomic_write_text, config_hash, file_sha256
from distgprl.schema import (
    SCHEMA_VERSION,
    SOURCE_PATHS,
    SchemaVersionError,
    git_commit,
    library_versions,
    read_csv,
    read_json,
    result_meta,
    source_commit,
    write_csv,
    write_json,
)

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
