"""`distgprl mechanisms`: the mechanism table of a preset's runs.

The table's rule: docs/findings/protocol.md, rule 7.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from distgprl.cli.common import ConfigOption, PresetOption, RootOption, resolve_preset, user_errors


@user_errors
def mechanisms(
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("paper_figures"),
) -> None:
    """The mechanism table: reach vs TC range, shaping and regulariser shares (CSV, Markdown)."""
    from distgprl.config import load_config
    from distgprl.data import TASK_NAMES
    from distgprl.experiments.mechanisms import reach_rows
    from distgprl.report.mechanisms import write_mechanisms
    from distgprl.reward_scale import describe_reward_scale

    preset = resolve_preset(preset, config)
    for task in TASK_NAMES:  # protocol rule 1's two ratios, from the preset's reward scale
        typer.echo(describe_reward_scale(load_config(preset, task=task).env, task))
    written, verdicts = write_mechanisms(root, preset, out_dir, reach_rows(root, preset))
    for line in verdicts:
        typer.echo(line)
    for path in written:
        typer.echo(f"wrote {path}")
