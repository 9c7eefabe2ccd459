"""What the `distgprl` commands share: the typer app, its command class, the options several
commands take, the preset a command runs and the handling of bad input (`user_errors`: exit
code 2 and one line on stderr). The commands themselves are registered in
`distgprl.cli`."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import typer
from typer.core import TyperCommand, TyperGroup

from distgprl import __version__
from distgprl.config import preset_with_overrides, register_preset, shipped_presets
from distgprl.data import TASK_NAMES
from distgprl.errors import UserInputError
from distgprl.identity import SWEEP_SEEDS
from distgprl.methods import METHODS
from distgprl.studies import STUDIES, is_study


def _plain_flags(params: list) -> list:
    """``params`` with no type shown for flags: they take no value, so typer's ``<bool>`` in
    the help only reads as if they did."""
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


class _Command(TyperCommand):
    """A typer command whose help shows no ``<bool>`` for flags (`_plain_flags`)."""

    def get_params(self, ctx):
        return _plain_flags(super().get_params(ctx))


class _Group(TyperGroup):
    """The typer group of `_Command`: the same for the top-level options."""

    def get_params(self, ctx):
        return _plain_flags(super().get_params(ctx))


app = typer.Typer(
    cls=_Group,
    add_completion=False,
    no_args_is_help=True,
    help="Dist-GPRL reproduction: fit, simulate, train, evaluate, report.",
)
command = functools.partial(app.command, cls=_Command)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"distgprl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Dist-GPRL reproduction: fit, simulate, train, evaluate, report."""


def user_errors(func):
    """Turn `UserInputError` into one clear line on stderr and exit code 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except UserInputError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(code=2) from None

    return wrapper


# Names the options take, for their help.
TRAINABLE_HELP = " | ".join(name for name, spec in METHODS.items() if spec.trainable)
METHODS_HELP = " | ".join(METHODS)
TASKS_HELP = " | ".join(TASK_NAMES)
PRESETS_HELP = " | ".join(shipped_presets())

# Options several commands share.
RootOption = Annotated[
    Path, typer.Option(help="Results root folder (runs go to <root>/<preset>/...).")
]
PresetOption = Annotated[
    str | None,
    typer.Option(
        metavar="NAME",
        help=f"Shipped preset: {PRESETS_HELP} (default paper), or one with overrides as "
        "--set names it (PRESET+SECTION.KEY=VALUE).",
        show_default=False,
    ),
]
SweepPresetOption = Annotated[
    str | None,
    typer.Option(
        "--preset",
        metavar="NAME",
        help=f"Shipped preset: {PRESETS_HELP} (default paper), or a study: "
        f"{' | '.join(STUDIES)} (its readings' presets, distgprl.studies).",
        show_default=False,
    ),
]
ConfigOption = Annotated[
    Path | None,
    typer.Option(
        "--preset-file",
        metavar="PATH",
        help="Your own preset YAML instead of --preset (the presets' schema; `extends: paper` "
        "takes paper's values for every key it does not set); the preset's name is the file "
        "stem, which must not be a shipped preset's.",
    ),
]
SetOption = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="SECTION.KEY=VALUE",
        help="Override one value of the preset (repeatable; the value is read as YAML, e.g. "
        "--set sac.batch_size=128). The runs are those of the preset named "
        "PRESET+SECTION.KEY=VALUE (their own folder and config hash; that name is what "
        "--preset takes to address them later).",
        show_default=False,
    ),
]
MethodsOption = Annotated[
    str | None, typer.Option(help=f"Comma-separated methods (default all): {METHODS_HELP}.")
]
TasksOption = Annotated[
    str | None, typer.Option(help=f"Comma-separated tasks (default all): {TASKS_HELP}.")
]
DEFAULT_SEEDS = ",".join(str(seed) for seed in SWEEP_SEEDS)
SeedsOption = Annotated[
    str | None,
    typer.Option(
        help=f"Comma-separated seeds (default: {DEFAULT_SEEDS}; for a study its seeds, then "
        "its pre-registered rules' runs at further seeds).",
        show_default=False,
    ),
]
TaskOption = Annotated[str, typer.Option(metavar="TASK", help=f"Task: {TASKS_HELP}.")]


def resolve_preset(
    preset: str | None, config: Path | None, overrides: list[str] | None = None
) -> str:
    """The preset a command runs: ``--preset`` (default ``paper``), or the user's
    ``--preset-file`` registered under its stem (`register_preset`), with the ``--set``
    overrides on top (`preset_with_overrides`: the name carries them)."""
    if config is None:
        name = preset or "paper"
    elif preset is not None:
        raise UserInputError("give --preset or --preset-file, not both")
    else:
        name = register_preset(config)
    if not overrides:
        return name
    if is_study(name):
        raise UserInputError(f"--set applies to one preset; {name!r} is a study of several")
    return preset_with_overrides(name, overrides)


def runs_text(count: int) -> str:
    """``"1 run"``, ``"2 runs"``: a count of runs in words."""
    return f"{count} run" if count == 1 else f"{count} runs"


def split_list(text: str | None) -> list[str] | None:
    """The items of a comma-separated option (None if it was not given or is empty)."""
    return [item.strip() for item in text.split(",") if item.strip()] if text else None


def parse_seeds(text: str | None) -> list[int] | None:
    """The seeds of ``--seeds`` (comma-separated integers; None when not given, so a study
    plans its own); a clear error otherwise."""
    if text is None:
        return None
    try:
        return [int(s) for s in split_list(text) or []]
    except ValueError:
        raise UserInputError(f"--seeds must be comma-separated integers, got {text!r}") from None


def given_options(ctx: typer.Context, *names: str) -> list[str]:
    """The options among ``names`` (the command's parameter names) that the command line gave,
    as it spells them (``--seed``, ``--no-repair-evaluations``), in the command's order; an
    option left at its default is not one. For refusing an option that would have no effect."""
    given = []
    for param in ctx.command.params:
        source = ctx.get_parameter_source(param.name) if param.name in names else None
        # by name: typer's ParameterSource is its own copy of click's
        if source is None or source.name in ("DEFAULT", "DEFAULT_MAP"):
            continue
        secondary: list[str] = getattr(param, "secondary_opts", None) or []
        negated = bool(secondary) and ctx.params.get(param.name) is False
        given.append((secondary if negated else param.opts)[0])
    return given


def main() -> None:
    """Console entry for `python -m distgprl` and `python -m distgprl.cli`."""
    app(prog_name="distgprl")
