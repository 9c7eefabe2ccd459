"""The `distgprl` command line: each command parses, loads a config, calls one function.

Bad input (unknown names, invalid files) exits with code 2 and one line on stderr. The
commands live in `distgprl.cli.runs` (train, evaluate, sweep, status),
`distgprl.cli.outputs` (tables, curves, render, bench), `distgprl.cli.mechanisms`
(mechanisms), `distgprl.cli.skills` (fit, hap) and `distgprl.cli.trials` (hardware);
`distgprl.cli.common` holds what they share. They are
registered here, in the order ``distgprl --help`` lists them.
"""

from __future__ import annotations

from distgprl.cli.common import app, command, main
from distgprl.cli.mechanisms import mechanisms
from distgprl.cli.outputs import bench, curves, render, tables
from distgprl.cli.runs import evaluate, status, sweep, train
from distgprl.cli.skills import fit, hap
from distgprl.cli.trials import hardware

for _function in (
    fit,
    hardware,
    bench,
    sweep,
    status,
    tables,
    mechanisms,
    curves,
    train,
    evaluate,
    render,
    hap,
):
    command()(_function)

__all__ = ["app", "main"]
