"""The public API re-exported by distgprl/__init__.py is typed for type checkers and IDEs:
mypy (``--strict``) reveals each lazily imported name of a user's script as the signature of
its definition in `distgprl.api`, never ``Any``, and reports a misspelt name."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mypy import api as mypy_api

import distgprl

PACKAGE_PARENT = Path(distgprl.__file__).resolve().parents[1]
NAMES = ("Policy", "evaluate", "fit_skill", "load_policy", "make_env", "train")

USER_SCRIPT = "\n".join(
    [
        "import distgprl",
        "import distgprl.api",
        "from distgprl import load_policy",
        *(f"reveal_type(distgprl.{name})  # root {name}" for name in NAMES),
        *(f"reveal_type(distgprl.api.{name})  # api {name}" for name in NAMES),
        'policy = load_policy("dcp", "dist-gprl", 0, preset="ci", root="runs")',
        "reveal_type(policy)  # loaded",
        'reveal_type(distgprl.train("dcp", "dist-gprl"))  # folder',
        "reveal_type(distgprl.__version__)  # version",
        'distgprl.trian("dcp", "dist-gprl")  # misspelt',
        "",
    ]
)

# Only the package, numpy and gymnasium's Env (what the API's annotations name) are
# analysed; every other third-party module is skipped (Any), which keeps a cold run to seconds.
MYPY_CONFIG = """\
[mypy]
follow_imports = skip
[mypy-distgprl,distgprl.*,numpy,numpy.*,gymnasium,gymnasium.core]
follow_imports = silent
"""


@pytest.fixture(scope="module")
def revealed(tmp_path_factory, monkeypatch_module):
    """Line comment (e.g. ``root train``) -> the type mypy reveals there, and mypy's errors."""
    folder = tmp_path_factory.mktemp("typed_api")
    (folder / "user.py").write_text(USER_SCRIPT)
    (folder / "mypy.ini").write_text(MYPY_CONFIG)
    monkeypatch_module.setenv("MYPYPATH", str(PACKAGE_PARENT))  # the code under test
    stdout, stderr, _ = mypy_api.run(
        [
            "--strict",
            "--config-file", str(folder / "mypy.ini"),
            "--cache-dir", str(folder / "cache"),
            "--no-error-summary",
            str(folder / "user.py"),
        ]
    )  # fmt: skip
    assert not stderr, stderr
    lines = USER_SCRIPT.splitlines()
    types, errors = {}, {}
    for match in re.finditer(r"user\.py:(\d+): (note|error): (.*)", stdout):
        label = lines[int(match[1]) - 1].split("# ")[-1]
        if match[2] == "note":
            types[label] = match[3].removeprefix('Revealed type is "').removesuffix('"')
        else:
            errors[label] = match[3]
    return types, errors


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


@pytest.mark.parametrize("name", NAMES)
def test_each_lazy_name_has_its_definitions_type(revealed, name):
    """``distgprl.<name>`` is a function or class (``def (...) -> ...``), exactly as typed as
    ``distgprl.api.<name>`` (lazily imported at run time, ``Any`` without the stubs)."""
    types, _ = revealed
    assert types[f"root {name}"].startswith("def (")
    assert types[f"root {name}"] == types[f"api {name}"]


def test_calls_return_the_real_types(revealed):
    types, errors = revealed
    assert types["loaded"] == "distgprl.api.Policy"
    assert types["folder"] == "pathlib.Path"
    assert types["version"] == "str"
    assert types["root Policy"].endswith("-> distgprl.api.Policy")
    assert types["root fit_skill"].endswith("-> distgprl.experiments.skills.FitOutput")
    assert types["root make_env"].endswith("-> gymnasium.core.Env[Any, Any]")
    assert not {label: error for label, error in errors.items() if label != "misspelt"}


def test_a_misspelt_name_is_an_error_not_any(revealed):
    _, errors = revealed
    assert 'Module has no attribute "trian"' in errors["misspelt"]
