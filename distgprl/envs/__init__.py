"""Gymnasium environments: the adaptation MDP and the windowed-weights ProMP-RRL residual MDP
(Table I's ProMP-RRL, residual RL at 10 Hz, is `distgprl.envs.residual_control_env`, built by
`distgprl.experiments.factories.make_env`, not registered).

Registered ids (``gymnasium.make(id, method=...)``), one pair per task of
`distgprl.data.TASK_NAMES`:

- ``DistGPRL-DCP-v<N>``, ``DistGPRL-DBM-v<N>``: `distgprl.envs.via_point_env.AdaptationEnv`;
- ``ProMPRRL-DCP-v<N>``, ``ProMPRRL-DBM-v<N>``: `distgprl.envs.windowed_residual_env.ResidualEnv`,

N the environment version, `distgprl.config_types.ENVIRONMENT_VERSION`. ``import distgprl``
registers them without importing gymnasium: if gymnasium's registry is loaded they are
registered at once, otherwise as soon as it loads (a finder on `sys.meta_path` waits for
``gymnasium.envs.registration``, then removes itself; the ids are computed only then).
Gymnasium 1.x reads no plugin entry points; ``gymnasium.make("distgprl:DistGPRL-DCP-v<N>")``
imports the package itself.
"""

from __future__ import annotations

import sys
from importlib.machinery import ModuleSpec
from importlib.util import find_spec
from types import ModuleType
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from importlib.abc import Loader

ENTRY_POINTS: dict[str, str] = {
    "DistGPRL": "distgprl.envs.via_point_env:AdaptationEnv",
    "ProMPRRL": "distgprl.envs.windowed_residual_env:ResidualEnv",
}
"""Id prefix -> the environment class its ids create (``module:Class``)."""

_REGISTRY_MODULE = "gymnasium.envs.registration"


def environment_id(prefix: str, task: str) -> str:
    """The gymnasium id of ``task``'s environment, ``<prefix>-<TASK>-v<ENVIRONMENT_VERSION>``."""
    from distgprl.config_types import ENVIRONMENT_VERSION

    return f"{prefix}-{task.upper()}-v{ENVIRONMENT_VERSION}"


def register_environments() -> None:
    """Register every task's ids in gymnasium's registry (ids already there are kept)."""
    from gymnasium.envs.registration import register, registry

    from distgprl.data import TASK_NAMES

    for task in TASK_NAMES:
        for prefix, entry_point in ENTRY_POINTS.items():
            env_id = environment_id(prefix, task)
            if env_id not in registry:
                register(id=env_id, entry_point=entry_point, kwargs={"task": task})


class _ThenCall:
    """A module loader that runs ``then`` after the module it wraps has executed."""

    def __init__(self, loader: Loader, then: Callable[[], None]) -> None:
        self.loader = loader
        self.then = then

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self.loader.exec_module(module)
        self.then()

    def __getattr__(self, name: str) -> object:
        """Everything else (``get_source``, ``get_filename``, ...) from the wrapped loader."""
        return getattr(self.__dict__["loader"], name)


class _RegisterWhenGymnasiumLoads:
    """Finds nothing itself: when ``gymnasium.envs.registration`` is first imported it leaves
    `sys.meta_path` and wraps that module's loader to call `register_environments` after it."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname != _REGISTRY_MODULE:
            return None
        sys.meta_path.remove(self)
        spec = find_spec(fullname)
        if spec is not None and spec.loader is not None:
            spec.loader = cast("Loader", _ThenCall(spec.loader, register_environments))
        return spec


def register_when_gymnasium_loads() -> None:
    """Register the ids now if gymnasium's registry is loaded, else once it loads."""
    if _REGISTRY_MODULE in sys.modules:
        register_environments()
    elif not any(isinstance(finder, _RegisterWhenGymnasiumLoads) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegisterWhenGymnasiumLoads())


register_when_gymnasium_loads()
