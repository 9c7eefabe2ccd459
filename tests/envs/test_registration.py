"""The gymnasium ids (distgprl/envs/__init__.py): ``import distgprl`` registers every task's
``DistGPRL-``/``ProMPRRL-<TASK>-v<N>`` without importing gymnasium, whichever of the two is
imported first, and ``gymnasium.make`` builds the right environment from them."""

from __future__ import annotations

import subprocess
import sys


def run(code: str) -> str:
    """``code`` in a fresh interpreter (the import order is the property); its stdout."""
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_import_distgprl_registers_the_ids_once_gymnasium_loads():
    out = run(
        "import sys, distgprl\n"
        "assert 'gymnasium' not in sys.modules and 'numpy' not in sys.modules\n"
        "import gymnasium\n"
        "from distgprl.config_types import ENVIRONMENT_VERSION\n"
        "from distgprl.data import TASK_NAMES\n"
        "for task in TASK_NAMES:\n"
        "    for prefix, cls in (('DistGPRL', 'via_point_env:AdaptationEnv'),\n"
        "                        ('ProMPRRL', 'windowed_residual_env:ResidualEnv')):\n"
        "        spec = gymnasium.spec(f'{prefix}-{task.upper()}-v{ENVIRONMENT_VERSION}')\n"
        "        assert spec.entry_point == 'distgprl.envs.' + cls, spec\n"
        "        assert spec.kwargs == {'task': task}, spec\n"
        "assert not [f for f in sys.meta_path if 'Gymnasium' in type(f).__name__]\n"
        "env = gymnasium.make(f'DistGPRL-DCP-v{ENVIRONMENT_VERSION}', method='dist-gprl')\n"
        "print(type(env.unwrapped).__name__, env.unwrapped.task_name); env.close()\n"
    )
    assert out.split()[-2:] == ["AdaptationEnv", "dcp"]


def test_ids_are_registered_when_gymnasium_was_imported_first():
    out = run(
        "import gymnasium, distgprl\n"
        "print(sorted(i for i in gymnasium.registry if i.startswith(('DistGPRL', 'ProMPRRL'))))"
    )
    from distgprl.config_types import ENVIRONMENT_VERSION

    assert out.strip() == str(
        sorted(
            f"{prefix}-{task}-v{ENVIRONMENT_VERSION}"
            for prefix in ("DistGPRL", "ProMPRRL")
            for task in ("DBM", "DCP")
        )
    )


def test_gymnasium_make_imports_the_package_from_a_module_prefixed_id():
    """Gymnasium 1.x reads no plugin entry points; ``"distgprl:<id>"`` is its way to make an
    environment of a package that was not imported."""
    from distgprl.config_types import ENVIRONMENT_VERSION

    out = run(
        "import sys, gymnasium\n"
        "assert 'distgprl' not in sys.modules\n"
        f"env = gymnasium.make('distgprl:ProMPRRL-DBM-v{ENVIRONMENT_VERSION}')\n"
        "print(type(env.unwrapped).__name__, env.unwrapped.task_name); env.close()\n"
    )
    assert out.split()[-2:] == ["ResidualEnv", "dbm"]
