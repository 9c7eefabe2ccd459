"""Preset validation (distgprl/config.py): every mistake in a preset is one clear
`UserInputError` line naming the key, the value and what was expected, never a silent
fallback to a default or a raw Python traceback."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from distgprl import config as config_module
from distgprl.config import load_config
from distgprl.config_types import Config, EnvConfig
from distgprl.errors import UserInputError


@pytest.fixture
def preset_dir(tmp_path, monkeypatch):
    """A preset folder of its own; `write(text)` writes ``t.yaml`` there."""
    monkeypatch.setattr(config_module, "PRESET_DIR", tmp_path)

    def write(text: str) -> str:
        (tmp_path / "t.yaml").write_text(text)
        return "t"

    return write


def test_unknown_task_under_tasks_is_an_error_not_silently_ignored(preset_dir):
    """A misspelt task (``dmb`` for ``dbm``) under ``tasks:`` is rejected whichever task is
    loaded, instead of the override silently never applying."""
    preset = preset_dir("tasks:\n  dmb:\n    run:\n      total_steps: 45000\n")
    for task in (None, "dcp", "dbm"):
        with pytest.raises(UserInputError, match=r"unknown task\(s\) dmb under tasks; valid: dcp"):
            load_config(preset, task=task)


def test_known_task_overrides_still_apply(preset_dir):
    preset = preset_dir("tasks:\n  dbm:\n    run:\n      total_steps: 45000\n  dcp:\n")
    assert load_config(preset, task="dbm").run.total_steps == 45_000
    assert load_config(preset, task="dcp").run == Config().run


@pytest.mark.parametrize(
    ("section", "line", "message"),
    [
        ("env", "correlation_lambda: abc", "correlation_lambda must be a number, got 'abc'"),
        ("env", "lambda_ga: [1, 2]", r"lambda_ga must be a number, got \[1, 2\]"),
        ("sac", "net_arch: 256", "net_arch must be a list, got 256"),
        ("sac", "net_arch: abc", "net_arch must be a list, got 'abc'"),
        (
            "sac",
            "net_arch: [256, wide]",
            r"net_arch must be a list of integers, got \[256, 'wide'\]",
        ),
        ("run", "total_steps: 30000.5", "total_steps must be an integer, got 30000.5"),
        ("run", "eval_every: true", "eval_every must be an integer, got True"),
        ("env", "clearance_timing: 3", "clearance_timing must be a string, got 3"),
    ],
)
def test_a_value_of_the_wrong_type_is_one_line_naming_key_value_and_type(
    preset_dir, section, line, message
):
    """``float("abc")`` / ``tuple(256)`` no longer escape as a raw ValueError / TypeError."""
    preset = preset_dir(f"{section}:\n  {line}\n")
    with pytest.raises(UserInputError, match=message) as caught:
        load_config(preset)
    assert "\n" not in str(caught.value) and "t.yaml" in str(caught.value)


def test_clearance_timing_is_checked_when_the_preset_is_loaded(preset_dir):
    """Only "predicted" and "current" load; anything else fails at load time (not first
    when an environment is built)."""
    preset = preset_dir("env:\n  clearance_timing: predicetd\n")
    with pytest.raises(
        UserInputError, match="clearance_timing must be 'predicted' or 'current', got 'predicetd'"
    ):
        load_config(preset)
    with pytest.raises(UserInputError, match="clearance_timing must be"):
        load_config(preset_dir(""), overrides={"env": {"clearance_timing": "now"}})
    for timing in ("predicted", "current"):
        preset = preset_dir(f"env:\n  clearance_timing: {timing}\n")
        assert load_config(preset).env.clearance_timing == timing


def test_valid_values_convert_as_before(preset_dir):
    """Integers (and YAML 1.1's unsigned exponents like ``1e-2``, which PyYAML reads as
    strings) for float fields become floats and lists become tuples, so a preset
    spelling a default value gives exactly the default configuration (and its hash)."""
    preset = preset_dir(
        "env:\n  correlation_lambda: 1e-2\n  sd_beta: 5e-4\n  progress_weight: 10\n"
        "sac:\n  net_arch: [256, 256]\n"
    )
    config = load_config(preset)
    assert config.env == EnvConfig() and config.sac == Config().sac
    assert isinstance(config.env.progress_weight, float)
    assert config.to_dict() == {**Config().to_dict(), "preset": "t"}


def test_sections_and_task_entries_must_be_mappings(preset_dir):
    for text, message in [
        ("env: 5\n", "a section must be a mapping of keys, got 5"),
        ("tasks: [dcp]\n", r"tasks must be a mapping of task names, got \['dcp'\]"),
        ("tasks:\n  dbm: 7\n", "tasks.dbm: must be a mapping of sections, got 7"),
        ("- env\n", "a preset must be a mapping of sections"),
    ]:
        preset = preset_dir(text)
        with pytest.raises(UserInputError, match=message):
            load_config(preset, task="dbm")


def test_correlation_length_scale_is_hashed_only_when_set(preset_dir):
    """The option added after the paper runs (0 = the fitted kernel) leaves the recorded
    configuration, and so every committed run's config hash, as it was; a set value is
    recorded."""
    default = load_config(preset_dir("")).to_dict()
    assert "correlation_length_scale" not in default["env"]
    assert default["env"]["correlation_lambda"] == 0.01
    changed = load_config(preset_dir("env:\n  correlation_length_scale: 0.1\n")).to_dict()
    assert changed["env"]["correlation_length_scale"] == 0.1
    assert {k: v for k, v in changed["env"].items() if k != "correlation_length_scale"} == (
        default["env"]
    )


def test_a_negative_correlation_length_scale_is_refused_at_load_time(preset_dir):
    with pytest.raises(UserInputError, match="correlation_length_scale = -0.1 must be > 0"):
        load_config(preset_dir("env:\n  correlation_length_scale: -0.1\n"))


# -- shipped presets and the user's own (--preset-file PATH) -----------------------------------
@pytest.fixture
def no_user_presets(monkeypatch):
    """No user preset registered, and whatever a test registers undone afterwards."""
    monkeypatch.setenv(config_module.USER_PRESETS_ENV, "")


def test_shipped_presets_are_package_data_not_files_of_the_checkout():
    """The presets live inside the package (what a wheel ships), read via importlib.resources."""
    from importlib import resources

    assert config_module.shipped_presets() == (
        "ci",
        "operator-correlation",
        "operator-signal",
        "operator-signal-uncoupled",
        "operator-unit",
        "paper",
    )
    shipped = resources.files("distgprl") / "presets" / "ci.yaml"
    assert shipped.is_file()
    assert load_config("ci").run.total_steps == 240


def test_a_user_preset_is_named_after_its_stem_and_loads_like_a_shipped_one(
    tmp_path, no_user_presets
):
    """A copy of `ci` registered as ``mine`` resolves to `ci`'s values under the name
    ``mine``, per task too."""
    from importlib import resources

    text = (resources.files("distgprl") / "presets" / "ci.yaml").read_text()
    (tmp_path / "mine.yaml").write_text(text)
    assert config_module.register_preset(tmp_path / "mine.yaml") == "mine"
    assert "mine" in config_module.preset_names()
    for task in (None, "dcp", "dbm"):
        assert load_config("mine", task=task) == replace(
            load_config("ci", task=task), preset="mine"
        )


def test_a_user_presets_run_hash_does_not_depend_on_where_the_file_is(
    tmp_path, monkeypatch, no_user_presets
):
    """The same file in two folders gives the same run (config hash), so moving a preset
    file never makes its runs stale."""
    from distgprl.identity import resolve_run

    hashes = []
    for folder in ("a", "b/c"):
        monkeypatch.setenv(config_module.USER_PRESETS_ENV, "")
        path = tmp_path / folder / "mine.yaml"
        path.parent.mkdir(parents=True)
        path.write_text("run:\n  total_steps: 300\n")
        config_module.register_preset(path)
        hashes.append(resolve_run("dcp", "dist-gprl", 0, "mine").hash)
    assert hashes[0] == hashes[1]
    assert hashes[0] != resolve_run("dcp", "dist-gprl", 0, "paper").hash


def test_a_user_preset_may_not_take_a_shipped_presets_name(tmp_path, no_user_presets):
    (tmp_path / "paper.yaml").write_text("run:\n  total_steps: 300\n")
    with pytest.raises(UserInputError, match="'paper' is a shipped preset's"):
        config_module.register_preset(tmp_path / "paper.yaml")
    assert load_config("paper").run.total_steps == 30_000


def test_two_files_of_one_stem_are_refused(tmp_path, no_user_presets):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "mine.yaml").write_text("")
    config_module.register_preset(tmp_path / "a" / "mine.yaml")
    config_module.register_preset(tmp_path / "a" / "mine.yaml")  # the same file again is fine
    with pytest.raises(UserInputError, match="registered already from"):
        config_module.register_preset(tmp_path / "b" / "mine.yaml")


def test_a_user_preset_that_does_not_load_is_reported_and_not_registered(tmp_path, no_user_presets):
    """The mistake is one line naming the file; the bad file is not left registered."""
    for text, message in [
        ("run:\n  total_stepz: 3\n", "unknown key"),
        ("a: [\n", "not valid YAML"),
    ]:
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        with pytest.raises(UserInputError, match=message) as caught:
            config_module.register_preset(path)
        assert "\n" not in str(caught.value) and "bad.yaml" in str(caught.value)
        assert "bad" not in config_module.preset_names()
    with pytest.raises(UserInputError, match="no such file"):
        config_module.register_preset(tmp_path / "missing.yaml")


# -- extends: a preset that modifies another ---------------------------------------------------
def test_a_preset_that_extends_another_is_its_parent_with_its_own_values_on_top(preset_dir):
    """For each task the parent's configuration (its ``tasks`` entry included) is resolved
    first, then the child's sections, then the child's ``tasks`` entry."""
    folder = config_module.PRESET_DIR
    (folder / "base.yaml").write_text(
        "sac:\n  batch_size: 64\n  learning_starts: 30\nrun:\n  total_steps: 300\n"
        "tasks:\n  dbm:\n    run:\n      total_steps: 600\n      eval_every: 30\n"
    )
    child = preset_dir(
        "extends: base\nsac:\n  batch_size: 32\ntasks:\n  dbm:\n    sac:\n      batch_size: 16\n"
    )
    dcp, dbm = load_config(child, task="dcp"), load_config(child, task="dbm")
    assert dcp.preset == dbm.preset == "t"
    assert (dcp.sac.batch_size, dcp.sac.learning_starts, dcp.run.total_steps) == (32, 30, 300)
    assert (dbm.sac.batch_size, dbm.run.total_steps, dbm.run.eval_every) == (16, 600, 30)
    assert load_config(child).run == replace(Config().run, total_steps=300)


def test_a_childs_section_overrides_its_parents_task_entry(preset_dir):
    """The parent resolved for the task comes first: the child's ``run.total_steps`` wins over
    the parent's ``tasks.dbm.run.total_steps`` (what "override only what differs" means)."""
    (config_module.PRESET_DIR / "base.yaml").write_text(
        "tasks:\n  dbm:\n    run:\n      total_steps: 600\n      eval_every: 30\n"
    )
    child = preset_dir("extends: base\nrun:\n  total_steps: 900\n")
    dbm = load_config(child, task="dbm")
    assert (dbm.run.total_steps, dbm.run.eval_every) == (900, 30)


def test_extends_chains_through_several_parents(preset_dir):
    folder = config_module.PRESET_DIR
    (folder / "a.yaml").write_text("sac:\n  batch_size: 64\n  learning_starts: 30\n")
    (folder / "b.yaml").write_text("extends: a\nsac:\n  learning_starts: 60\n")
    config = load_config(preset_dir("extends: b\nrun:\n  total_steps: 300\n"))
    assert (config.sac.batch_size, config.sac.learning_starts, config.run.total_steps) == (
        64,
        60,
        300,
    )


@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({"t": "extends: t\n"}, r"extends makes a cycle \(t -> t\)"),
        ({"t": "extends: a\n", "a": "extends: t\n"}, r"extends makes a cycle \(t -> a -> t\)"),
        ({"t": "extends: nowhere\n"}, "unknown preset 'nowhere'"),
        ({"t": "extends: [a]\n"}, r"extends must be a preset name, got \['a'\]"),
        ({"t": "extends: a\n", "a": "sac:\n  batchsize: 3\n"}, r"a.yaml: unknown key\(s\) sac"),
    ],
)
def test_a_bad_parent_is_one_error_naming_the_file(preset_dir, files, message):
    for name, text in files.items():
        (config_module.PRESET_DIR / f"{name}.yaml").write_text(text)
    with pytest.raises(UserInputError, match=message) as caught:
        load_config("t")
    assert "\n" not in str(caught.value)


# -- dotted overrides (--set section.key=value) ------------------------------------------------
def test_overrides_give_one_canonical_name_that_resolves_to_the_preset_with_those_values():
    name = config_module.preset_with_overrides(
        "ci", ["sac.learning_rate=3e-4", "sac.batch_size=32", "run.total_steps = 300"]
    )
    assert name == "ci+run.total_steps=300+sac.batch_size=32+sac.learning_rate=0.0003"
    config = load_config(name, task="dbm")
    assert config.preset == name
    assert config == replace(
        load_config("ci", task="dbm"),
        preset=name,
        sac=replace(load_config("ci").sac, batch_size=32, learning_rate=3e-4),
        run=replace(load_config("ci").run, total_steps=300),
    )
    assert config_module.preset_with_overrides("ci", []) == "ci"


@pytest.mark.parametrize(
    ("override", "value"),
    [
        ("sac.net_arch=[64, 32]", (64, 32)),
        ("sac.hap_hinge=true", True),
        ("env.clearance_timing=current", "current"),
        ("sac.learning_rate=1e20", 1e20),  # repr 1e+20: the name must not hold the separator
        ("env.sd_d_min=1", 1.0),  # an integer for a float field
    ],
)
def test_every_kind_of_value_reads_back_from_the_name(override, value):
    name = config_module.preset_with_overrides("ci", [override])
    assert name.count(config_module.OVERRIDE_SEPARATOR) == 1
    section, key = override.split("=")[0].split(".")
    assert getattr(getattr(load_config(name), section), key) == value


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["sac.batchsize=128"], r"unknown key sac.batchsize; valid: learning_rate, "),
        (["sack.batch_size=128"], r"unknown section 'sack'; valid: env, sac, run"),
        (["sac.batch_size"], "expected section.key=value"),
        (["batch_size=128"], "expected section.key=value"),
        (["sac.batch_size=many"], "sac.batch_size must be an integer, got 'many'"),
        (["sac.batch_size=[1"], "the value is not valid YAML"),
        (["sac.batch_size=1", "sac.batch_size=2"], "sac.batch_size is given twice"),
    ],
)
def test_a_bad_override_is_one_error_naming_it(overrides, message):
    with pytest.raises(UserInputError, match=message) as caught:
        config_module.preset_with_overrides("ci", overrides)
    assert "\n" not in str(caught.value)


def test_an_override_out_of_range_is_refused_when_the_preset_loads():
    with pytest.raises(UserInputError, match=r"--set: sac.batch_size = 0 must be >= 1"):
        load_config(config_module.preset_with_overrides("ci", ["sac.batch_size=0"]))


@pytest.mark.parametrize(
    "name", ["ci+sac.batch_size=32+run.total_steps=300", "ci+sac.learning_rate=3e-4"]
)
def test_a_name_written_other_than_the_canonical_way_is_refused_with_it(name):
    """One configuration, one name (one folder, one hash): unsorted keys or another spelling
    of a value are refused with the name to use."""
    with pytest.raises(UserInputError, match=re.escape("write it as 'ci+")):
        load_config(name)


def test_an_override_enters_the_run_hash_and_the_recorded_config():
    """`config.json` records ``run.to_dict()``: the name with its overrides and the value."""
    from distgprl.identity import resolve_run

    plain = resolve_run("dcp", "dist-gprl", 0, "paper")
    name = config_module.preset_with_overrides("paper", ["sac.batch_size=128"])
    changed = resolve_run("dcp", "dist-gprl", 0, name)
    assert changed.hash != plain.hash
    recorded = changed.to_dict()["config"]
    assert recorded["preset"] == "paper+sac.batch_size=128"
    assert recorded["sac"]["batch_size"] == 128
    same_value = config_module.preset_with_overrides("paper", ["sac.batch_size=256"])
    assert resolve_run("dcp", "dist-gprl", 0, same_value).hash != plain.hash


def test_a_user_preset_name_may_not_hold_the_override_separator(tmp_path, no_user_presets):
    (tmp_path / "a+b.yaml").write_text("")
    with pytest.raises(UserInputError, match="holds '\\+'"):
        config_module.register_preset(tmp_path / "a+b.yaml")
