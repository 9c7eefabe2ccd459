"""Configuration: frozen dataclasses with the paper's defaults, overridden by YAML presets.

A preset is shipped with the package (``distgprl/presets/<name>.yaml``, read with
`importlib.resources`, so an installed wheel has them) or is a user's own YAML file made
known with `register_preset` (the CLI's ``--preset-file PATH``; its name is the file stem). It
has one mapping per section (``env``, ``sac``, ``run``) and optional per-task overrides under
``tasks: {dcp: {env: {...}}}``. ``extends: NAME`` makes it the preset ``NAME`` with its own
values on top: the parent's configuration for the task is resolved first (its ``extends``
included), then the file's sections, then its ``tasks`` entry for the task.

A preset name may carry dotted overrides, ``paper+sac.batch_size=128+run.total_steps=300``
(`preset_with_overrides`, the CLI's ``--set``): the preset with those values on top, one
canonical name per configuration, so its runs have a folder and a config hash of their own
and every process that reads the name resolves the same configuration.

Unknown keys (sections, fields, task names under ``tasks``) are an error, so a typo in a
preset never silently falls back to a default; so is a value that does not convert to its
field's type, or a ``clearance_timing`` other than ``"predicted"`` / ``"current"``. So is a
number out of its field's range (`distgprl.config_checks.BOUNDS`: no negative weight, step
count or scale; counts of at least one), or a window layout that does not fit the via-points
(`distgprl.config_checks.check_config`). Every such error is one `ConfigError` line (a
`ValueError`, and a `UserInputError`: the CLI exits 2) naming the file, the dotted key
(``run.total_steps``), the value and what was expected.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import fields, replace
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import yaml

from distgprl.config_checks import check_config
from distgprl.config_types import (
    Config,
    EnvConfig,
    RunConfig,
    SACConfig,
)
from distgprl.data import TASK_NAMES
from distgprl.errors import ConfigError, UserInputError
from distgprl.reward_scale import check_reward_scale

PRESET_DIR: Traversable | Path = resources.files("distgprl") / "presets"
"""The shipped presets (package data)."""

USER_PRESETS_ENV = "DISTGPRL_USER_PRESETS"
"""Environment variable listing the user's preset files (`os.pathsep`-separated absolute
paths) that `register_preset` made known: how a sweep's worker processes, which inherit the
environment, find a ``--preset-file`` preset by its name. A user may set it too, to name
their files as presets without ``--preset-file`` (docs/reference/config.md)."""

EXTENDS_KEY = "extends"
"""The top-level key of a preset naming the preset it modifies."""

OVERRIDE_SEPARATOR = "+"
"""Separates a preset name from each of its dotted overrides (`preset_with_overrides`)."""


__all__ = [
    "EXTENDS_KEY",
    "OVERRIDE_SEPARATOR",
    "PRESET_DIR",
    "USER_PRESETS_ENV",
    "load_config",
    "parse_override",
    "preset_names",
    "preset_with_overrides",
    "register_preset",
    "shipped_presets",
]


_SECTIONS = {"env": EnvConfig, "sac": SACConfig, "run": RunConfig}


CHOICES: dict[str, tuple[str, ...]] = {
    "clearance_timing": ("predicted", "current"),
    "covariance_scale": ("zero-mean", "signal", "unit", "correlation", "signal-uncoupled"),
    "action_scale_rule": ("reach", "fixed"),
}
"""Fields that take one of a few strings; checked when a configuration is loaded."""


def _convert(key: str, value: Any, default: Any, where: str, section: str) -> Any:
    """``value`` converted to the type of the field ``section.key``'s ``default``, or a
    `ConfigError` naming the key, the value and the expected type."""

    def bad(expected: str) -> ConfigError:
        name = f"{section}.{key}"
        return ConfigError(f"{where}: {name} must be {expected}, got {value!r}", name)

    if isinstance(default, tuple):
        if isinstance(value, str | bytes) or not isinstance(value, list | tuple):
            raise bad("a list")
        kinds = {type(item) for item in default}
        if kinds <= {int} and not all(_is_int(item) for item in value):
            raise bad("a list of integers")
        return tuple(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(default, int):
        if not _is_int(value):
            raise bad("an integer")
        return value
    if isinstance(default, float):
        return _finite_number(value, bad)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise bad("a string")
        if key in CHOICES and value not in CHOICES[key]:
            raise bad(" or ".join(repr(choice) for choice in CHOICES[key]))
        return value
    return value


def _finite_number(value: Any, bad: Callable[[str], ConfigError]) -> float:
    """``value`` as a finite float (a bool is not a number), else ``bad``'s error."""
    if isinstance(value, bool):
        raise bad("a number")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise bad("a number") from None
    if not math.isfinite(number):
        raise bad("a finite number")
    return number


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _apply(section_cls, current, overrides: Any, where: str, section: str):
    """``current`` (a section's dataclass) with ``overrides`` (that section's mapping of one
    layer) applied, each value converted to its field's type (`_convert`)."""
    if not isinstance(overrides, dict):
        raise ConfigError(
            f"{where}: {section}: a section must be a mapping of keys, got {overrides!r}", section
        )
    names = {f.name: f for f in fields(section_cls)}
    unknown = sorted(set(overrides) - set(names), key=str)
    if unknown:
        dotted = [f"{section}.{key}" for key in unknown]
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(dotted)}; valid: {', '.join(names)}", dotted[0]
        )
    values = {
        key: _convert(key, value, getattr(current, key), where, section)
        for key, value in overrides.items()
    }
    return replace(current, **values)


def shipped_presets() -> tuple[str, ...]:
    """Names of the presets shipped with the package, sorted."""
    return tuple(
        sorted(
            p.name.removesuffix(".yaml") for p in PRESET_DIR.iterdir() if p.name.endswith(".yaml")
        )
    )


def _user_presets() -> dict[str, Path]:
    """The registered user presets: name (file stem) -> file."""
    paths = [Path(p) for p in os.environ.get(USER_PRESETS_ENV, "").split(os.pathsep) if p]
    return {path.stem: path for path in paths}


def register_preset(path: str | Path) -> str:
    """Make a user's YAML file (same schema as the shipped presets) a preset named after its
    stem, for this process and the processes it starts (`USER_PRESETS_ENV`); return that name.

    The file is loaded once here, so a mistake in it is reported before any run starts. Its
    location does not enter any config hash: the same file elsewhere gives the same runs.

    Raises:
        UserInputError: the file does not exist, does not load, its stem is a shipped preset's
            name or holds `OVERRIDE_SEPARATOR`, or another file of the same stem is registered
            already.
    """
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ConfigError(f"--preset-file {path}: no such file")
    if path.suffix not in (".yaml", ".yml"):
        raise ConfigError(f"--preset-file {path}: expected a .yaml file")
    name = path.stem
    if name in shipped_presets():
        raise ConfigError(
            f"--preset-file {path}: its name {name!r} is a shipped preset's (shipped: "
            f"{', '.join(shipped_presets())}); rename the file so its runs are not mistaken "
            "for the shipped preset's"
        )
    if OVERRIDE_SEPARATOR in name:
        raise ConfigError(
            f"--preset-file {path}: its name {name!r} holds {OVERRIDE_SEPARATOR!r}, which "
            "separates a preset from its --set overrides; rename the file"
        )
    registered = _user_presets()
    if name in registered and registered[name] != path:
        raise ConfigError(
            f"--preset-file {path}: a preset named {name!r} is registered already from "
            f"{registered[name]}; rename one of the files"
        )
    if name in registered:
        return name
    previous = os.environ.get(USER_PRESETS_ENV)
    os.environ[USER_PRESETS_ENV] = os.pathsep.join(
        [*(str(p) for p in registered.values()), str(path)]
    )
    try:
        for task in (None, *TASK_NAMES):
            load_config(name, task=task)
    except UserInputError:  # a file that does not load is not left registered
        if previous is None:
            del os.environ[USER_PRESETS_ENV]
        else:
            os.environ[USER_PRESETS_ENV] = previous
        raise
    return name


def preset_names() -> tuple[str, ...]:
    """Every preset `load_config` resolves: the shipped ones, then the registered ones."""
    return shipped_presets() + tuple(sorted(set(_user_presets()) - set(shipped_presets())))


def _preset_text(preset: str) -> tuple[str, str]:
    """(YAML text, where it came from) of a preset, or a `UserInputError` listing the valid
    names."""
    shipped = PRESET_DIR / f"{preset}.yaml"
    if shipped.is_file():
        return shipped.read_text(), str(shipped)
    user = _user_presets().get(preset)
    if user is not None:
        try:
            return user.read_text(), str(user)
        except OSError as exc:
            raise ConfigError(f"preset {preset!r} ({user}): {exc.strerror}") from None
    raise ConfigError(
        f"unknown preset {preset!r}; valid presets: {', '.join(preset_names())} "
        "(or --preset-file PATH for a YAML file of your own)",
        "preset",
    )


# -- dotted overrides: ``--set section.key=value`` ------------------------------------------


def _format_value(value: Any) -> str:
    """A converted field value as the name of a preset with overrides writes it: YAML that
    reads back as the same value, without `OVERRIDE_SEPARATOR` (``1e20``, not ``1e+20``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple):
        return "[" + ",".join(_format_value(item) for item in value) + "]"
    if isinstance(value, float):
        return repr(value).replace("e+", "e")
    return str(value)


def parse_override(text: str) -> tuple[str, str, Any]:
    """``"section.key=value"`` as (section, key, value): the value read as YAML (a scalar, or
    a flow list such as ``[128,128]`` for a list field) and converted to the field's type.

    Raises:
        ConfigError: not ``section.key=value``, an unknown section or key (named, with the
            valid ones), a value that is not YAML or does not convert to the field's type.
    """
    where = f"--set {text}"
    dotted, equals, value_text = text.partition("=")
    section, dot, key = dotted.strip().partition(".")
    if not equals or not dot or not key or not value_text.strip():
        raise ConfigError(f"{where}: expected section.key=value (e.g. sac.batch_size=128)")
    if section not in _SECTIONS:
        raise ConfigError(
            f"{where}: unknown section {section!r}; valid: {', '.join(_SECTIONS)}", section
        )
    names = [item.name for item in fields(_SECTIONS[section])]
    if key not in names:
        raise ConfigError(
            f"{where}: unknown key {section}.{key}; valid: {', '.join(names)}", f"{section}.{key}"
        )
    try:
        value = yaml.safe_load(value_text)
    except yaml.YAMLError:
        raise ConfigError(f"{where}: the value is not valid YAML", f"{section}.{key}") from None
    default = getattr(getattr(Config(), section), key)
    return section, key, _convert(key, value, default, where, section)


def preset_with_overrides(preset: str, overrides: list[str] | tuple[str, ...]) -> str:
    """The name of ``preset`` with the dotted overrides ``overrides`` (``section.key=value``,
    `parse_override`) on top: ``paper+sac.batch_size=128``, the keys sorted and each value
    written as `_format_value` writes it, so one configuration has one name.

    Raises:
        ConfigError: a bad override (`parse_override`), a key given twice, or ``preset``
            already carrying overrides.
    """
    if OVERRIDE_SEPARATOR in preset:
        raise ConfigError(f"preset {preset!r} has overrides already; give them all with --set")
    values: dict[str, str] = {}
    for text in overrides:
        section, key, value = parse_override(text)
        dotted = f"{section}.{key}"
        if dotted in values:
            raise ConfigError(f"--set {text}: {dotted} is given twice", dotted)
        values[dotted] = _format_value(value)
    parts = [preset, *(f"{dotted}={values[dotted]}" for dotted in sorted(values))]
    return OVERRIDE_SEPARATOR.join(parts)


def _split_overrides(preset: str) -> tuple[str, dict[str, dict[str, Any]]]:
    """(base preset, overrides by section) of a preset name with overrides; a `ConfigError`
    if the name is not the canonical one `preset_with_overrides` gives."""
    base, *parts = preset.split(OVERRIDE_SEPARATOR)
    sections: dict[str, dict[str, Any]] = {}
    for text in parts:
        section, key, value = parse_override(text)
        sections.setdefault(section, {})[key] = value
    canonical = preset_with_overrides(base, parts)
    if canonical != preset:
        raise ConfigError(
            f"preset {preset!r}: write it as {canonical!r} (keys sorted, each once, values "
            "as --set writes them), the one name of this configuration",
            "preset",
        )
    return base, sections


# -- resolving a preset ----------------------------------------------------------------------

_Layer = tuple[Any, str, str]
"""A layer of values, where it was set (for messages) and its dotted name (for errors)."""


def _read_preset(preset: str) -> tuple[dict[str, Any], str]:
    """(mapping, file) of a preset's YAML, its ``tasks`` entry checked."""
    text, path = _preset_text(preset)
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        raise ConfigError(f"{path}: not valid YAML ({detail})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a preset must be a mapping of sections, got {data!r}")
    tasks = data.get("tasks") or {}
    if not isinstance(tasks, dict):
        raise ConfigError(f"{path}: tasks must be a mapping of task names, got {tasks!r}", "tasks")
    unknown_tasks = sorted(set(tasks) - set(TASK_NAMES), key=str)
    if unknown_tasks:
        raise ConfigError(
            f"{path}: unknown task(s) {', '.join(map(str, unknown_tasks))} under tasks; "
            f"valid: {', '.join(TASK_NAMES)}",
            f"tasks.{unknown_tasks[0]}",
        )
    return data, path


def _preset_layers(
    preset: str, task: str | None, chain: tuple[str, ...] = ()
) -> tuple[list[_Layer], str]:
    """(The layers a preset's configuration for ``task`` is built from, first to last: its
    parent's (``extends``, recursively), then its own sections, then its ``tasks`` entry;
    the preset's file)."""
    data, path = _read_preset(preset)
    layers: list[_Layer] = []
    parent = data.get(EXTENDS_KEY)
    if parent is not None:
        if not isinstance(parent, str):
            raise ConfigError(f"{path}: extends must be a preset name, got {parent!r}", "extends")
        if parent in (*chain, preset):
            cycle = " -> ".join((*chain, preset, parent))
            raise ConfigError(f"{path}: extends makes a cycle ({cycle})", "extends")
        layers = _preset_layers(parent, task, (*chain, preset))[0]
    own = {key: value for key, value in data.items() if key not in ("tasks", EXTENDS_KEY)}
    layers.append((own, path, ""))
    tasks = data.get("tasks") or {}
    if task is not None and task in tasks:
        layers.append((tasks[task] or {}, f"{path}: tasks.{task}", f"tasks.{task}"))
    return layers, path


def load_config(
    preset: str = "paper",
    task: str | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
) -> Config:
    """Resolve a preset (its parents, the task's overrides in each, the dotted overrides its
    name carries) into a `Config`; ``overrides`` (by section) go on top.

    ``preset`` is a shipped preset's name or a registered user preset's (`register_preset`),
    with or without dotted overrides (`preset_with_overrides`); `Config.preset` is that name.

    Raises:
        ConfigError: the preset is unknown, not YAML, or has a key, a value or a combination
            of values that is wrong (module docstring); one line naming the file and the key.
    """
    base, dotted = _split_overrides(preset) if OVERRIDE_SEPARATOR in preset else (preset, {})
    layers, path = _preset_layers(base, task)
    if dotted:
        layers.append((dotted, "--set", "--set"))
    if overrides:
        layers.append((overrides, "overrides", "overrides"))
    config = Config(preset=preset)
    origin = {"": path}  # where each key's value was last set, for `check_config`
    for layer, where, name in layers:
        if not isinstance(layer, dict):
            raise ConfigError(f"{where}: must be a mapping of sections, got {layer!r}", name)
        unknown = sorted(set(layer) - set(_SECTIONS), key=str)
        if unknown:
            raise ConfigError(
                f"{where}: unknown section(s) {', '.join(map(str, unknown))}; valid: "
                f"{', '.join(_SECTIONS)}",
                str(unknown[0]),
            )
        for section, cls in _SECTIONS.items():
            if layer.get(section):
                updated = _apply(cls, getattr(config, section), layer[section], where, section)
                config = replace(config, **{section: updated})
                origin.update({f"{section}.{key}": where for key in layer[section]})
    check_config(config, origin)
    check_reward_scale(
        config.env, origin.get("env.progress_weight", path), (task,) if task else TASK_NAMES
    )
    return config
