"""The texts every report table is written as: Markdown pipe tables and CSV (by pandas)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import pandas as pd


def markdown_table(title: str | None, header: list[str], rows: list[list[str]]) -> str:
    """A Markdown pipe table, under ``title`` and a blank line if given."""
    lines = [] if title is None else [title, ""]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    return "\n".join(lines) + "\n"


def csv_text(rows: Iterable[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """``rows`` as CSV under the header ``columns`` (`pandas.DataFrame.to_csv`, ``\\n`` line
    ends, fields quoted where needed): each value as `str` writes it (a float its shortest
    repr, NaN ``nan``), a cell a row lacks or holds None empty, keys beyond ``columns`` left
    out."""
    cells = [{c: "" if row.get(c) is None else row[c] for c in columns} for row in rows]
    frame = pd.DataFrame(cells, columns=list(columns), dtype=object)
    return frame.to_csv(index=False, lineterminator="\n", na_rep="nan")
