"""The test folders have no ``__init__.py`` and pytest imports test modules by their
basename (the default ``prepend`` import mode), so two test modules with the same file name
in different folders break collection of the whole suite."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def test_test_module_basenames_are_unique():
    names = Counter(path.name for path in TESTS.rglob("test_*.py"))
    assert not [name for name, count in names.items() if count > 1]
