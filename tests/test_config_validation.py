"""Bad configurations (issue 52, item 4): a ``--preset-file`` YAML with an unknown key, a value of
the wrong type, zero or negative steps, a negative lambda weight or a window larger than the
via-points is one `ConfigError` (a `ValueError`) naming the key from the Python API, and exit
code 2 with that one line from the CLI; random valid values load as given; the CLI's numeric
options refuse non-positive counts (and negative seeds) with exit code 2.

Property tests (hypothesis) draw the keys, values and options; the example tests pin one
case of each class through ``distgprl train --preset-file``."""

from __future__ import annotations

import math
import pickle
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from distgprl import api
from distgprl import config as config_module
from distgprl.cli import app
from distgprl.config import CHOICES, load_config
from distgprl.config_checks import BOUNDS, NON_NEGATIVE
from distgprl.config_types import Config, EnvConfig
from distgprl.errors import ConfigError, UserInputError
from distgprl.reward_scale import check_reward_scale
from distgprl.schema import EVALUATION_SEED, TRAINING_CURVE_SEED

DEFAULTS = Config()
SECTIONS = ("env", "sac", "run")
FIELD_DEFAULTS: dict[str, dict[str, Any]] = {
    section: {f.name: getattr(getattr(DEFAULTS, section), f.name) for f in fields(section_cls)}
    for section, section_cls in zip(
        SECTIONS, (type(DEFAULTS.env), type(DEFAULTS.sac), type(DEFAULTS.run)), strict=True
    )
}
ALL_FIELDS = [(section, name) for section in SECTIONS for name in FIELD_DEFAULTS[section]]


def is_number(value: Any) -> bool:
    """An int or float (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


NUMERIC_FIELDS = [(s, n) for s, n in ALL_FIELDS if is_number(FIELD_DEFAULTS[s][n])]
LAMBDA_FIELDS = [(s, n) for s, n in NUMERIC_FIELDS if "lambda" in n]
STEP_FIELDS = [("run", name) for name in FIELD_DEFAULTS["run"]]
PROPERTY = settings(max_examples=60, deadline=None, database=None)  # no .hypothesis/ folder
WIDE = {"COLUMNS": "250", "TERMINAL_WIDTH": "250", "NO_COLOR": "1"}


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A folder for the only preset `load_preset` loads."""
    return tmp_path_factory.mktemp("presets")


@contextmanager
def preset_file(folder: Path, data: Any) -> Iterator[str]:
    """``data`` written as YAML to the only preset of ``folder``; its name, while the block
    runs (the shipped presets hidden, no user preset registered)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(config_module, "PRESET_DIR", folder)
        patch.setenv(config_module.USER_PRESETS_ENV, "")
        (folder / "t.yaml").write_text(yaml.safe_dump(data, allow_unicode=True))
        yield "t"


def load_preset(folder: Path, data: Any, **kwargs: Any) -> Config:
    """`load_config` of ``data`` as a preset file (`preset_file`)."""
    with preset_file(folder, data) as name:
        return load_config(name, **kwargs)


def config_error(folder: Path, data: Any) -> ConfigError:
    """The `ConfigError` loading ``data`` as a preset raises, for every task (as
    `register_preset` loads it); fails the test if it loads."""
    errors = []
    with preset_file(folder, data) as name:
        for task in (None, "dcp", "dbm"):
            with pytest.raises(ConfigError) as caught:
                load_config(name, task=task)
            errors.append(caught.value)
    assert len({(str(e), e.key) for e in errors}) == 1  # the same error whichever task
    return errors[0]


def assert_names(error: ConfigError, key: str) -> None:
    """``error`` is one line naming ``key`` (its ``key`` attribute too) and the file, and is
    both a `ValueError` and a `UserInputError` (exit 2 at the CLI); it survives pickling."""
    message = str(error)
    assert error.key == key and key in message, (key, message)
    assert "\n" not in message and "t.yaml" in message
    assert isinstance(error, ValueError) and isinstance(error, UserInputError)
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), str(copy), copy.key) == (ConfigError, message, key)


# -- strategies ---------------------------------------------------------------------------
KEY_TEXT = st.text(
    st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Zl", "Zp")),
    min_size=1,
    max_size=20,
)
"""Key names: any printable text on one line."""


def parses_as_float(text: str) -> bool:
    """Whether ``float(text)`` accepts ``text`` (``"1e-2"``, ``" 3 "``, ``"nan"``)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


SCALARS = {
    "int": st.integers(-(10**6), 10**6),
    "float": st.floats(allow_nan=False, allow_infinity=False, width=32),
    "bool": st.booleans(),
    "text": st.text(max_size=10),
    "none": st.none(),
    "list": st.lists(st.integers(-5, 5), max_size=3),
    "mapping": st.dictionaries(st.text(max_size=3), st.integers(), min_size=1, max_size=2),
}


def wrong_values(default: Any, name: str) -> st.SearchStrategy:
    """Values of a type the field whose default is ``default`` does not take."""
    if isinstance(default, tuple):
        non_int = st.one_of(SCALARS["float"], SCALARS["bool"], SCALARS["text"])
        return st.one_of(
            SCALARS["int"],
            SCALARS["float"],
            SCALARS["bool"],
            SCALARS["text"],
            SCALARS["none"],
            SCALARS["mapping"],
            st.lists(non_int, min_size=1, max_size=3).map(lambda items: [64, *items]),
        )
    if isinstance(default, bool):
        kinds = ("int", "float", "text", "none", "list", "mapping")
    elif isinstance(default, int):
        kinds = ("float", "bool", "text", "none", "list", "mapping")
    elif isinstance(default, float):
        text = SCALARS["text"].filter(lambda t: not parses_as_float(t))
        others = [SCALARS[k] for k in ("bool", "none", "list", "mapping")]
        return st.one_of(text, *others)
    else:  # a string
        kinds = ("int", "float", "bool", "none", "list", "mapping")
        if name in CHOICES:  # a string, but none of the few it takes
            choices = CHOICES[name]
            return st.one_of(
                SCALARS["text"].filter(lambda t: t not in choices), *(SCALARS[k] for k in kinds)
            )
    return st.one_of(*(SCALARS[kind] for kind in kinds))


def negative_values(default: Any) -> st.SearchStrategy:
    """Negative values of a numeric (or list-of-numbers) field's type."""
    negative_ints = st.integers(max_value=-1)
    if isinstance(default, tuple):
        return st.lists(st.integers(1, 512), max_size=2).flatmap(
            lambda widths: negative_ints.map(lambda bad: [*widths, bad])
        )
    if isinstance(default, float):  # YAML ints are numbers too
        return st.one_of(
            st.floats(max_value=-1e-12, allow_nan=False, allow_infinity=False), negative_ints
        )
    return negative_ints


def value_in(name: str, default: Any) -> st.SearchStrategy:
    """Values the field ``name`` (``section.key``) with ``default`` admits."""
    key = name.split(".")[1]
    bound = BOUNDS.get(name, NON_NEGATIVE)
    if isinstance(default, bool):
        return st.booleans()
    if isinstance(default, str):
        return st.sampled_from(CHOICES[key]) if key in CHOICES else st.just(default)
    if isinstance(default, tuple):
        return st.lists(st.integers(max(1, math.ceil(bound.low)), 512), min_size=1, max_size=3)
    if isinstance(default, int):
        low = math.floor(bound.low) + 1 if bound.strict else math.ceil(bound.low)
        return st.integers(low, low + 100_000)
    high = bound.high if bound.high is not None else 1e6
    return st.floats(bound.low, high, exclude_min=bound.strict, allow_nan=False)


@st.composite
def valid_configs(draw) -> dict[str, dict[str, Any]]:
    """A random valid preset: windows that fit the via-points, steps that are multiples of
    the episode, every other field drawn (or left out) within its range."""
    n_windows = draw(st.integers(1, 4))
    window_size = draw(st.integers(2, 6))
    least = n_windows * (window_size - 1) + 3
    data: dict[str, dict[str, Any]] = {
        "env": {
            "n_windows": n_windows,
            "window_size": window_size,
            "n_via_points": draw(st.integers(least, least + 10)),
        },
        "sac": {},
        "run": {
            key: n_windows * draw(st.integers(1, 20_000))
            for key in ("total_steps", "eval_every", "checkpoint_every")
        },
    }
    for section, name in ALL_FIELDS:
        if name in data[section] or not draw(st.booleans()):
            continue
        data[section][name] = draw(value_in(f"{section}.{name}", FIELD_DEFAULTS[section][name]))
    assume(_keeps_reward_purpose(data["env"]))
    return data


def _keeps_reward_purpose(env: dict[str, Any]) -> bool:
    """Whether ``env``'s values (over the defaults) meet protocol v8 rule 1's bounds on every
    task (a configuration that breaks them is bad input, `test_reward_scale.py`)."""
    values = EnvConfig(**{**FIELD_DEFAULTS["env"], **env})
    try:
        check_reward_scale(values, "random")
    except ConfigError:
        return False
    return True


# -- the config loader ----------------------------------------------------------------------
@PROPERTY
@given(
    section=st.sampled_from(SECTIONS),
    keys=st.lists(KEY_TEXT, min_size=1, max_size=3, unique=True),
    valid=valid_configs(),
)
def test_unknown_keys_are_one_error_naming_the_first(folder, section, keys, valid):
    """Unknown keys among valid ones in any section: the error names the first unknown key
    (sorted) as ``section.key``, and the message lists every unknown one."""
    unknown = [key for key in keys if key not in FIELD_DEFAULTS[section]]
    if not unknown:
        return
    valid[section].update({key: 1 for key in unknown})
    error = config_error(folder, valid)
    dotted = [f"{section}.{key}" for key in sorted(unknown)]
    assert_names(error, dotted[0])
    assert all(name in str(error) for name in dotted)


@PROPERTY
@given(name=KEY_TEXT)
def test_an_unknown_section_is_an_error_naming_it(folder, name):
    """A top-level key that is no section (nor ``tasks``) names itself."""
    if name in (*SECTIONS, "tasks"):
        return
    assert_names(config_error(folder, {name: {"total_steps": 3}}), name)


@PROPERTY
@given(field=st.sampled_from(ALL_FIELDS), data=st.data())
def test_a_value_of_a_wrong_type_is_an_error_naming_its_key(folder, field, data):
    """Any field given a value of a type it does not take (a string for a number, a float
    for a count, a number for a flag, a list for a scalar, null, a mapping; a string
    outside a choice field's few) is one error naming ``section.key``."""
    section, name = field
    value = data.draw(wrong_values(FIELD_DEFAULTS[section][name], name))
    assert_names(config_error(folder, {section: {name: value}}), f"{section}.{name}")


@PROPERTY
@given(field=st.sampled_from(NUMERIC_FIELDS + [("sac", "net_arch")]), data=st.data())
def test_a_negative_number_is_an_error_naming_its_key(folder, field, data):
    """No numeric field (weights, penalties, scales, distances, counts, steps; a layer width)
    takes a negative value."""
    section, name = field
    value = data.draw(negative_values(FIELD_DEFAULTS[section][name]))
    error = config_error(folder, {section: {name: value}})
    assert_names(error, f"{section}.{name}")
    assert "must be" in str(error)


def test_the_lambda_and_step_fields_are_the_ones_the_issue_names():
    """The property tests below draw from the lambda weights and the run's step counts: the
    lists are complete, so those tests cannot pass by drawing from nothing."""
    assert set(LAMBDA_FIELDS) >= {
        ("env", "correlation_lambda"),
        ("env", "lambda_ga"),
        ("sac", "lambda_sim"),
        ("sac", "lambda_hap"),
        ("sac", "lambda_velocity"),
        ("sac", "lambda_acceleration"),
    }
    assert {"total_steps", "eval_every", "checkpoint_every"} <= {n for _, n in STEP_FIELDS}


@PROPERTY
@given(
    field=st.sampled_from(LAMBDA_FIELDS),
    value=st.floats(max_value=-1e-300, allow_nan=False, allow_infinity=False),
)
def test_a_negative_lambda_is_an_error_naming_it(folder, field, value):
    """λ < 0, for any of the lambda weights (S's regulariser, r_ga's, L_sim's and its terms',
    L_hap's), however small."""
    section, name = field
    assert_names(config_error(folder, {section: {name: value}}), f"{section}.{name}")


@PROPERTY
@given(field=st.sampled_from(STEP_FIELDS), value=st.integers(max_value=0))
def test_zero_or_negative_steps_are_an_error_naming_the_key(folder, field, value):
    """Total steps, curve / checkpoint periods, episode counts, threads: zero or negative
    is refused (zero is a multiple of every episode length, so this is its own check)."""
    section, name = field
    error = config_error(folder, {section: {name: value}})
    assert_names(error, f"{section}.{name}")
    assert "must be >= 1" in str(error)


@PROPERTY
@given(n_via_points=st.integers(2, 40), excess=st.integers(1, 40))
def test_a_window_larger_than_the_via_points_is_an_error_naming_it(folder, n_via_points, excess):
    """``env.window_size`` > ``env.n_via_points``: one error naming the window size and
    saying it is larger than the via-points."""
    env = {"n_via_points": n_via_points, "window_size": n_via_points + excess}
    error = config_error(folder, {"env": env})
    assert_names(error, "env.window_size")
    assert f"is larger than env.n_via_points = {n_via_points}" in str(error)


@PROPERTY
@given(n_windows=st.integers(1, 5), window_size=st.integers(2, 10), short=st.integers(1, 5))
def test_windows_that_do_not_fit_the_via_points_are_an_error_naming_the_window(
    folder, n_windows, window_size, short
):
    """Windows no larger than the via-points that still do not fit (K windows of L,
    overlapping by one, after the start point and before the last two, need K (L - 1) + 3)
    are refused at load time, not first when an environment is built."""
    n_via_points = max(window_size, n_windows * (window_size - 1) + 3 - short)
    env = {"n_windows": n_windows, "window_size": window_size, "n_via_points": n_via_points}
    run = {key: 3 * n_windows for key in ("total_steps", "eval_every", "checkpoint_every")}
    error = config_error(folder, {"env": env, "run": run})
    assert_names(error, "env.window_size")


@PROPERTY
@given(data=valid_configs())
def test_random_valid_values_load_as_given(folder, data):
    """A preset of random valid values loads, every value as written (floats as floats,
    lists as tuples), from the file and as overrides alike."""
    from_file = load_preset(folder, data)
    for section, values in data.items():
        for name, value in values.items():
            loaded = getattr(getattr(from_file, section), name)
            expected = tuple(value) if isinstance(value, list) else value
            assert loaded == expected and type(loaded) is type(FIELD_DEFAULTS[section][name])
    from_overrides = load_preset(folder, {}, overrides=data)
    assert from_overrides.to_dict() == from_file.to_dict()


# -- the CLI --------------------------------------------------------------------------------
def never_run(*args: Any, **kwargs: Any) -> None:
    """Stands in for training and sweeping: a check that let bad input through must fail
    the test, not start a run."""
    raise AssertionError("bad input reached a training run or a sweep")


@contextmanager
def no_runs() -> Iterator[None]:
    """While the block runs, starting a run's training or a sweep fails (`never_run`), and
    no user preset is registered."""
    from distgprl.experiments import sweep, training

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(training, "_train_locked", never_run)
        patch.setattr(sweep, "run_sweep", never_run)
        patch.setenv(config_module.USER_PRESETS_ENV, "")
        yield


BAD_CONFIGS = [
    ("unknown key", "run:\n  total_stepz: 300\n", "run.total_stepz"),
    ("unknown section", "runs:\n  total_steps: 300\n", "runs"),
    ("wrong type", "sac:\n  batch_size: large\n", "sac.batch_size"),
    ("wrong type (list)", "sac:\n  net_arch: 256\n", "sac.net_arch"),
    ("zero steps", "run:\n  total_steps: 0\n", "run.total_steps"),
    ("negative steps", "run:\n  total_steps: -300\n", "run.total_steps"),
    ("negative lambda", "sac:\n  lambda_hap: -0.2\n", "sac.lambda_hap"),
    ("negative lambda (env)", "env:\n  correlation_lambda: -1e-2\n", "env.correlation_lambda"),
    ("window > via-points", "env:\n  window_size: 16\n  n_via_points: 15\n", "env.window_size"),
    (
        "r_ga pays 30 % of a success",
        "env:\n  progress_weight: 1\n  success_bonus: 1\n",
        "env.progress_weight",
    ),
]


@pytest.mark.parametrize(
    ("text", "key"), [c[1:] for c in BAD_CONFIGS], ids=[c[0] for c in BAD_CONFIGS]
)
def test_train_with_a_bad_config_exits_2_with_one_line_naming_the_key(tmp_path, text, key):
    """`distgprl train --preset-file bad.yaml`: exit 2, stderr exactly one line naming the file
    and the key, no traceback, nothing written; the Python API raises the `ConfigError`."""
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    root = tmp_path / "results"
    args = ["train", "--method", "dist-gprl", "--task", "dcp", "--preset-file", str(path)]
    with no_runs():
        result = CliRunner().invoke(app, [*args, "--root", str(root)], env=WIDE)
    assert result.exit_code == 2, result.output
    [line] = result.stderr.splitlines()
    assert line.startswith(f"error: {path}: ") and key in line, line
    assert "Traceback" not in result.output and not root.exists()
    with no_runs(), pytest.raises(ValueError) as caught:
        api.train("dcp", "dist-gprl", config=path, root=root, progress=False)
    assert isinstance(caught.value, ConfigError) and caught.value.key == key
    assert not root.exists()


NON_POSITIVE_OPTIONS = [
    # (command and its other arguments, option, what the message names, smallest valid value)
    (["train", "--method", "dist-gprl", "--task", "dcp"], "--steps", "steps", 1),
    (["train", "--method", "dist-gprl", "--task", "dcp"], "--seed", "seed", 0),
    (["evaluate", "--method", "demo", "--task", "dcp"], "--episodes", "--episodes", 1),
    (["evaluate", "--method", "demo", "--task", "dcp"], "--seed", "seed", 0),
    (["sweep", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"], "--workers",
     "--workers", 1),
    (["sweep", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"], "--seeds", "seed", 0),
    (["sweep", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"], "--twin-trials",
     "--twin-trials", 0),
    (["sweep", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"], "--heartbeat",
     "--heartbeat", 0),
    (["status", "--preset", "ci"], "--workers", "--workers", 1),
    (["status", "--preset", "ci"], "--seeds", "seed", 0),
    (["fit", "--task", "dcp"], "--n-via-points", "--n-via-points", 2),
    (["hardware", "--method", "dist-gprl", "--task", "dbm"], "--trials", "--trials", 1),
]  # fmt: skip


@PROPERTY
@given(case=st.sampled_from(NON_POSITIVE_OPTIONS), below=st.integers(1, 10**9))
def test_numeric_options_below_their_least_value_exit_2(tmp_path_factory, case, below):
    """Every count option below its least value (steps, episodes, workers, trials, twin
    trials, via-points: non-positive; seeds and the heartbeat: negative) is refused with exit
    code 2 and a message naming it, before anything is written."""
    command, option, named, least = case
    root = tmp_path_factory.getbasetemp() / "never-written"
    value = str(least - below)
    extra = ["--root", str(root)] if command[0] != "fit" else ["--out-dir", str(root)]
    with no_runs():
        result = CliRunner().invoke(app, [*command, option, value, *extra], env=WIDE)
    assert result.exit_code == 2, (command, option, value, result.output)
    assert named in result.output and "Traceback" not in result.output
    assert not root.exists()


# each example plans a sweep through `status` (~0.6 s): fewer examples than `PROPERTY`'s
# (hypothesis tries the bounds first), the refusals above keep all of theirs
@settings(PROPERTY, max_examples=15)
@given(workers=st.integers(1, 10**6), seeds=st.lists(st.integers(0, 2**32 - 1), max_size=3))
def test_positive_workers_and_valid_seeds_are_accepted(tmp_path_factory, workers, seeds):
    """The same options at valid values pass: `status` (read-only) plans the runs."""
    root = tmp_path_factory.getbasetemp() / "empty-results"
    seeds = [seed for seed in seeds if seed not in (EVALUATION_SEED, TRAINING_CURVE_SEED)] or [0]
    args = ["status", "--preset", "ci", "--methods", "gprl-d", "--tasks", "dcp"]
    args += ["--seeds", ",".join(map(str, seeds)), "--workers", str(workers), "--root", str(root)]
    result = CliRunner().invoke(app, args, env={**WIDE, config_module.USER_PRESETS_ENV: ""})
    assert result.exit_code == 0, result.output
    assert "missing" in result.output


def test_a_bad_config_file_is_reported_wherever_the_api_loads_it(tmp_path):
    """`register_preset` (the API's ``config=`` and the CLI's ``--preset-file``) raises the same
    `ConfigError` as `load_config`, names the file, and leaves the file unregistered."""
    path = tmp_path / "mine.yaml"
    path.write_text("tasks:\n  dbm:\n    sac:\n      lambda_sim: -1\n")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(config_module.USER_PRESETS_ENV, "")
        with pytest.raises(ConfigError) as caught:
            config_module.register_preset(path)
        assert "mine" not in config_module.preset_names()
    assert caught.value.key == "sac.lambda_sim"
    assert str(caught.value).startswith(f"{path}: tasks.dbm: sac.lambda_sim = -1.0 must be >= 0")
    assert isinstance(caught.value, ValueError)


def test_the_shipped_presets_pass_the_checks():
    """Every shipped preset loads for every task (the ranges refuse nothing they use)."""
    for name in config_module.shipped_presets():
        for task in (None, "dcp", "dbm"):
            load_config(name, task=task)


def test_where_a_value_was_set_is_the_file_the_error_names(tmp_path):
    """A value out of range set by the task's override names ``tasks.<task>``; the same
    value from ``overrides`` names the overrides."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(config_module, "PRESET_DIR", tmp_path)
        (tmp_path / "t.yaml").write_text("tasks:\n  dbm:\n    run:\n      eval_every: 0\n")
        with pytest.raises(ConfigError, match=r"t\.yaml: tasks\.dbm: run\.eval_every = 0"):
            load_config("t", task="dbm")
        assert load_config("t", task="dcp").run == DEFAULTS.run
        with pytest.raises(ConfigError, match=r"^overrides: env\.sd_epsilon = 0\.0 must be > 0"):
            load_config("t", overrides={"env": {"sd_epsilon": 0}})


def test_a_file_that_is_not_yaml_is_one_line_with_no_key(tmp_path):
    """Errors about the file as a whole (not YAML) have an empty key and one line."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(config_module, "PRESET_DIR", tmp_path)
        (tmp_path / "t.yaml").write_text("run: [\n  total_steps: 3\n")
        with pytest.raises(ConfigError) as caught:
            load_config("t")
    assert caught.value.key == "" and "not valid YAML" in str(caught.value)
    assert "\n" not in str(caught.value)


def test_the_operator_choices_a_config_accepts_are_the_ones_the_layout_builds():
    """`CHOICES["covariance_scale"]` (checked when a config loads; config cannot import the
    layout) names exactly `COVARIANCE_SCALES`, each of which builds an action layout."""
    from distgprl.adaptation.layout import COVARIANCE_SCALES

    assert CHOICES["covariance_scale"] == COVARIANCE_SCALES
