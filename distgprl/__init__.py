"""distgprl: reproduction of Dist-GPRL (safety-aware GP skill adaptation with SAC).

The public API (`distgprl.api`) is re-exported lazily: ``distgprl.make_env``,
``distgprl.load_policy``, ``distgprl.train``, ``distgprl.evaluate``, ``distgprl.fit_skill``
and ``distgprl.Policy`` import their module on first use, so ``import distgprl`` loads neither
torch nor pybullet. Type checkers and IDEs see the real signatures (the imports under
``TYPE_CHECKING``). Importing the package also registers the gymnasium ids
``DistGPRL-<TASK>-v<N>`` / ``ProMPRRL-<TASK>-v<N>`` (`distgprl.envs`), without importing
gymnasium itself.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import distgprl.envs  # noqa: F401  (registers the gymnasium ids, lazily)
from distgprl.version import __version__

if TYPE_CHECKING:
    from distgprl.api import Policy as Policy
    from distgprl.api import evaluate as evaluate
    from distgprl.api import fit_skill as fit_skill
    from distgprl.api import load_policy as load_policy
    from distgprl.api import make_env as make_env
    from distgprl.api import train as train

_API = ("Policy", "evaluate", "fit_skill", "load_policy", "make_env", "train")
__all__ = ["Policy", "__version__", "evaluate", "fit_skill", "load_policy", "make_env", "train"]

if not TYPE_CHECKING:  # type checkers see the imports above; unknown names are errors to them

    def __getattr__(name: str) -> object:
        if name in _API:
            from distgprl import api

            return getattr(api, name)
        raise AttributeError(f"module 'distgprl' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
