"""The texts every report table is written as — Markdown pipe tables, LaTeX tables and CSV
(by pandas) — their cells' number formats, and the files they are written to."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from distgprl.io import atomic_write_text
from distgprl.schema import SCHEMA_VERSION, csv_meta_path


def markdown_table(title: str | None, header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown pipe table, under ``title`` and a blank line if given."""
    lines = [] if title is None else [title, ""]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    return "\n".join(lines) + "\n"


def number_text(value: Any, digits: int) -> str:
    """A number's cell: ``value`` to ``digits`` decimals, ``–`` where it is missing (None, an
    empty cell) or not finite."""
    if value is None or value == "" or not math.isfinite(float(value)):
        return "–"
    return f"{float(value):.{digits}f}"


def interval_text(point: float, low: float, high: float, digits: int = 2) -> str:
    """``0.67 [0.09, 0.99]``: `number_text` of ``point`` and its interval ``[low, high]``,
    the point alone where ``low`` is NaN (no interval)."""
    if math.isnan(low):
        return number_text(point, digits)
    return f"{number_text(point, digits)} [{low:.{digits}f}, {high:.{digits}f}]"


LATEX_SIGNS = {"±": "$\\pm$", "—": "---", "–": "--", "†": "$^\\dagger$"}
"""The Unicode signs of the tables and how LaTeX writes them."""


def latex_text(text: str) -> str:
    """``text`` with `LATEX_SIGNS` as LaTeX (ASCII text is unchanged)."""
    for sign, latex in LATEX_SIGNS.items():
        text = text.replace(sign, latex)
    return text


def latex_table(
    caption: str,
    label: str,
    columns: str,
    header: Sequence[str],
    rows: Iterable[Sequence[str]],
    footnote: str = "",
) -> str:
    """A LaTeX ``table`` float of a booktabs ``tabular``: ``header`` lines (each a whole row),
    a rule, a line per row of cells, ``footnote`` in small type; text through `latex_text`."""
    lines = ["\\begin{table}[htb]", "\\centering", f"\\caption{{{latex_text(caption)}}}"]
    lines += [f"\\label{{{label}}}", f"\\begin{{tabular}}{{{columns}}}", "\\toprule"]
    lines += [f"{line} \\\\" for line in header]
    lines += ["\\midrule", *(latex_text(" & ".join(cells)) + " \\\\" for cells in rows)]
    lines += ["\\bottomrule", "\\end{tabular}"]
    lines += ["", f"\\footnotesize {latex_text(footnote)}"] if footnote else []
    return "\n".join([*lines, "\\end{table}", ""])


def csv_text(
    rows: Iterable[Mapping[str, Any]], columns: Sequence[str], significant: int | None = None
) -> str:
    """``rows`` as CSV with header ``columns`` (pandas, ``\\n`` line ends): values as `str`
    writes them (NaN ``nan``) or, with ``significant``, numbers to that many significant
    digits (NaN empty); a missing or None cell empty, keys beyond ``columns`` dropped."""
    cells = [{c: "" if row.get(c) is None else row[c] for c in columns} for row in rows]
    frame = pd.DataFrame(cells, columns=list(columns), dtype=object)
    if significant is None:
        return frame.to_csv(index=False, lineterminator="\n", na_rep="nan")
    numbers = frame.infer_objects()
    return numbers.to_csv(
        index=False, lineterminator="\n", na_rep="", float_format=f"%.{significant}g"
    )


def table_meta_text(text: str, preset: str, description: str, **extra: Any) -> str:
    """The metadata sidecar (`csv_meta_path`) of a table's CSV ``text``, as
    `distgprl.schema.write_csv` writes one; no time or commit, so ``make tables`` is
    byte-identical."""
    columns = next(csv.reader([text.split("\n", 1)[0]]))
    meta = {"schema_version": SCHEMA_VERSION, "kind": "table", "preset": preset}
    meta |= {"description": description, **extra}
    return json.dumps({"meta": meta, "columns": columns}, indent=2) + "\n"


def write_table_files(
    stem: Path,
    suffixes: Sequence[str],
    texts: Sequence[str] | None,
    preset: str,
    description: str,
    **extra: Any,
) -> list[Path]:
    """Write ``texts`` (one per suffix) to ``stem`` + suffix, a CSV with its sidecar; with
    ``texts`` None (nothing to tabulate) remove those files, so no stale table is left."""
    paths = [Path(f"{stem}{suffix}") for suffix in suffixes]
    if texts is None:
        for path in paths:
            path.unlink(missing_ok=True)
            if path.suffix == ".csv":
                csv_meta_path(path).unlink(missing_ok=True)
        return []
    written = []
    for path, text in zip(paths, texts, strict=True):
        written.append(atomic_write_text(path, text))
        if path.suffix == ".csv":
            meta = table_meta_text(text, preset, description, **extra)
            written.append(atomic_write_text(csv_meta_path(path), meta))
    return written
