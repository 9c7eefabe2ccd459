"""``python -m distgprl.experiments.bench``: argparse entry (the typer CLI is `distgprl bench`)."""

from __future__ import annotations

import time
from pathlib import Path

from distgprl.experiments.bench.markdown import markdown_table
from distgprl.experiments.bench.run import load_results, run_benchmarks

__all__ = ["main"]

DESCRIPTION = (
    "Benchmarks (`distgprl bench [--quick]`): medians and spreads with warm-up and repeats."
)


def main(argv: list[str] | None = None) -> None:
    """``python -m distgprl.experiments.bench [--quick] [--out DIR]``: run and print the table."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m distgprl.experiments.bench", description=DESCRIPTION
    )
    parser.add_argument("--quick", action="store_true", help="fewer repeats and timed steps")
    parser.add_argument("--out", type=Path, default=Path("results/bench"))
    args = parser.parse_args(argv)
    start = time.perf_counter()
    path = run_benchmarks(
        args.quick,
        args.out,
        progress=lambda m: print(f"[bench {time.perf_counter() - start:5.1f} s] {m}", flush=True),
    )
    print(markdown_table(load_results(path)))
    print(f"wrote {path} and {path.with_suffix('.png')}")
