"""Figure files: PNG and PDF written byte-reproducibly, or removed when there is nothing to
draw (figures are functions of the current results only)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

from distgprl.io import atomic_write_bytes

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PNG_DPI = 150
METADATA = {"png": {"Software": None}, "pdf": {"CreationDate": None, "Producer": None}}
"""Per suffix, the metadata fixed so that the same results give the same bytes."""


def subplots(rows: int, columns: int, **options: Any) -> tuple[Figure, Any]:
    """`matplotlib.pyplot.subplots` on the non-interactive Agg backend: (figure, axes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, columns, **options)


def write_or_remove_figure(figure: tuple[Figure, int] | None, stem: str | Path) -> list[Path]:
    """Write ``(figure, number of things drawn)`` to ``<stem>.png`` and ``.pdf`` atomically and
    close it; with nothing drawn (or None) remove them. Returns the paths written."""
    fig, drawn = figure or (None, 0)
    written = []
    for suffix, metadata in METADATA.items():
        path = Path(f"{stem}.{suffix}")
        if fig is None or not drawn:
            path.unlink(missing_ok=True)
            continue
        buffer = io.BytesIO()
        fig.savefig(buffer, format=suffix, dpi=PNG_DPI, metadata=metadata)
        written.append(atomic_write_bytes(path, buffer.getvalue()))
    if fig is not None:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return written
