"""Figure files of the reports: PNG and PDF written byte-reproducibly, or removed when there is
nothing to draw (figures are functions of the current results only)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

from distgprl.io import atomic_write_bytes

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def subplots(rows: int, columns: int, **options: Any) -> tuple[Figure, Any]:
    """`matplotlib.pyplot.subplots` on the non-interactive Agg backend (figures go to files
    only): (figure, axes array)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, columns, **options)


PNG_DPI = 150
"""PNG resolution (dots per inch); the PDF is vector."""

SUFFIXES = ("png", "pdf")


def remove_figure(stem: str | Path) -> None:
    """Remove ``<stem>.png`` and ``<stem>.pdf`` if they exist (an earlier figure that the
    results no longer make)."""
    for suffix in SUFFIXES:
        Path(f"{stem}.{suffix}").unlink(missing_ok=True)


def write_or_remove_figure(figure: tuple[Figure, int], stem: str | Path) -> list[Path]:
    """Write a plot function's ``(figure, number of things drawn)`` to ``<stem>.png`` and
    ``<stem>.pdf`` atomically, with fixed metadata so that the same results give the same
    bytes, or, with nothing drawn, remove an earlier figure there (it would no longer match
    the results); close the figure either way. Returns the paths written."""
    import matplotlib.pyplot as plt

    fig, drawn = figure
    written = []
    for suffix in SUFFIXES if drawn else ():
        buffer = io.BytesIO()
        metadata = (
            {"Software": None} if suffix == "png" else {"CreationDate": None, "Producer": None}
        )
        fig.savefig(buffer, format=suffix, dpi=PNG_DPI, metadata=metadata)
        written.append(atomic_write_bytes(Path(f"{stem}.{suffix}"), buffer.getvalue()))
    if not drawn:
        remove_figure(stem)
    plt.close(fig)
    return written
