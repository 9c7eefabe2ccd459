"""The modules of ``scripts/`` (not a package: ``docs_pages``, ``readme_results``) and of
``benchmarks/``, for the tests that check what they write."""

from __future__ import annotations

import importlib.util
import sys
from functools import cache
from pathlib import Path
from types import ModuleType

REPOSITORY = Path(__file__).resolve().parents[1]


@cache
def load_script(name: str, folder: str = "scripts") -> ModuleType:
    """The module ``<folder>/<name>.py`` (``scripts/`` or ``benchmarks/``), loaded from its
    file (once per test process)."""
    spec = importlib.util.spec_from_file_location(name, REPOSITORY / folder / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # a dataclass looks its module up there
    spec.loader.exec_module(module)
    return module
