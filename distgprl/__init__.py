"""distgprl: reproduction of Dist-GPRL (safety-aware GP skill adaptation with SAC).

The public API (`distgprl.api`) is re-exported lazily: ``distgprl.make_env``,
``distgprl.load_policy``, ``distgprl.train``, ``distgprl.evaluate``, ``distgprl.fit_skill``
and ``distgprl.Policy`` import their module on first use, so ``import distgprl`` loads neither
torch nor pybullet.
"""

from __future__ import annotations

from typing import Any

from distgprl.version import __version__

_API = ("Policy", "evaluate", "fit_skill", "load_policy", "make_env", "train")
__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    if name in _API:
        from distgprl import api

        return getattr(api, name)
    raise AttributeError(f"module 'distgprl' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
