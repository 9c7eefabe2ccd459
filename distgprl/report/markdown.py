"""Markdown pipe tables, as every report table writes them."""

from __future__ import annotations


def markdown_table(title: str | None, header: list[str], rows: list[list[str]]) -> str:
    """A Markdown pipe table, under ``title`` and a blank line if given."""
    lines = [] if title is None else [title, ""]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    return "\n".join(lines) + "\n"
