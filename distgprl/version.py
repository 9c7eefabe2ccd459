"""The package's version, in a module of its own that imports nothing.

`distgprl.schema` stamps it into every result file; reading it from here rather than from the
package's ``__init__`` keeps the package free of import circles (``distgprl`` re-exports the
public API, which imports `distgprl.schema`). ``distgprl.__version__`` is the same string.
"""

from __future__ import annotations

__version__ = "0.1.0"
