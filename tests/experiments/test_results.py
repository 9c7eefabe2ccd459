"""distgprl/experiments/results.py re-exports the versioned-file API from its homes."""

from __future__ import annotations

from distgprl import io, schema
from distgprl.experiments import results


def test_results_re_exports_the_schema_and_io_objects():
    """Every name of ``results.__all__`` is the very object of distgprl.schema or distgprl.io
    (one implementation, so old callers write and check the same files)."""
    assert results.__all__
    for name in results.__all__:
        home = schema if hasattr(schema, name) else io
        assert getattr(results, name) is getattr(home, name), name
