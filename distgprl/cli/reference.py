"""The `distgprl` command line as one click command, for the documentation's CLI reference.

``docs/reference/cli.md`` renders `command` with mkdocs-click: the same click command, options
and help texts that ``distgprl <command> --help`` prints, built from the one typer app of
`distgprl.cli`, so the reference lists every command and cannot drift from the help. Nothing
else imports this module.
"""

from __future__ import annotations

import typer.main

from distgprl.cli import app

command = typer.main.get_command(app)
"""The typer app's click group: ``distgprl`` and its commands."""

__all__ = ["command"]
