"""Figure of a HAP safe subspace: C_safe in 3-D, coloured by joint path cost, with the
obstacles (matplotlib, imported only when drawing).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from distgprl.safety.hap_build import SafeSubspace
from distgprl.safety.shapes import Box, Cylinder, Plane, Shape

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d import Axes3D

__all__ = ["plot_subspace"]


def _draw_shape(axes: Axes3D, shape: Shape, extent: np.ndarray) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    colour = "tab:red" if shape.dynamic else "dimgray"
    if isinstance(shape, Box):
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        corners = shape.position + (signs * shape.half_extents) @ np.asarray(shape.rotation).T
        faces = [
            [0, 1, 3, 2],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 3, 7, 5],
        ]
        axes.add_collection3d(
            Poly3DCollection(
                [corners[f] for f in faces], facecolor=colour, alpha=0.25, edgecolor=colour
            )
        )
    elif isinstance(shape, Cylinder):
        angle = np.linspace(0, 2 * np.pi, 25)
        circle = np.stack((np.cos(angle), np.sin(angle), np.zeros_like(angle)), axis=1)
        rotation = np.asarray(shape.rotation)
        for z in (-shape.half_length, shape.half_length):
            ring = shape.position + (circle * shape.radius + [0, 0, z]) @ rotation.T
            axes.plot(*ring.T, color=colour, linewidth=1)
        for k in range(0, 24, 3):
            ends = np.array([[0, 0, -shape.half_length], [0, 0, shape.half_length]])
            ends[:, :2] = circle[k, :2] * shape.radius
            line = shape.position + ends @ rotation.T
            axes.plot(*line.T, color=colour, linewidth=1)
    elif isinstance(shape, Plane):
        normal = np.asarray(shape.normal, dtype=float) / np.linalg.norm(shape.normal)
        from distgprl.safety.edf import frame_from_normal

        frame = frame_from_normal(normal)
        half = 0.5 * np.max(extent[1] - extent[0]) + 0.1
        centre = np.asarray(shape.position, dtype=float)
        # Centre the patch under the plotted region (projected onto the plane).
        middle = extent.mean(axis=0)
        centre = middle - normal * (normal @ (middle - centre))
        square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
        corners = centre + square @ frame[:, :2].T
        axes.add_collection3d(
            Poly3DCollection([corners], facecolor="tan", alpha=0.2, edgecolor="none")
        )


def plot_subspace(
    subspace: SafeSubspace,
    shapes: Sequence[Shape],
    out_path: str | Path,
    *,
    title: str | None = None,
) -> Path:
    """Write a 3-D scatter PNG of C_safe (coloured by joint path cost) with the obstacles.

    Args:
        subspace: the subspace to draw.
        shapes: obstacle shapes to draw (static grey, dynamic red).
        out_path: PNG path (parent directories are created).
        title: figure title (default: size and build statistics).

    Returns:
        The written path.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    figure = Figure(figsize=(7, 6), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(projection="3d")
    config = subspace.config
    extent = np.array([config.workspace_lower, config.workspace_upper], dtype=float)
    if len(subspace):
        points = axes.scatter(
            *subspace.positions.T, c=subspace.costs, cmap="viridis", s=14, depthshade=False
        )
        figure.colorbar(
            points, ax=axes, shrink=0.6, pad=0.12, label="joint path cost from root (rad)"
        )
        root = subspace.positions[subspace.parents < 0]
        axes.scatter(*root.T, marker="*", s=120, color="tab:orange", label="root")
        axes.legend(loc="upper left")
    for shape in shapes:
        _draw_shape(axes, shape, extent)
    pad = 0.1
    bottom = min(extent[0, 2] - pad, 0.0)
    for shape in shapes:  # show horizontal planes (the table) below the grid
        if isinstance(shape, Plane) and abs(shape.normal[2]) > 0.9 * np.linalg.norm(shape.normal):
            bottom = min(bottom, float(shape.position[2]))
    limits = np.array(
        [
            [extent[0, 0] - pad, extent[1, 0] + pad],
            [extent[0, 1] - pad, extent[1, 1] + pad],
            [bottom, extent[1, 2] + pad],
        ]
    )
    axes.set_xlim(*limits[0])
    axes.set_ylim(*limits[1])
    axes.set_zlim(*limits[2])
    axes.set_box_aspect(limits[:, 1] - limits[:, 0])
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_zlabel("z (m)")
    stats = subspace.stats
    axes.set_title(
        title
        or f"HAP C_safe: {stats.n_mapped} mapped of {stats.n_reachable} reachable poses "
        f"({len(subspace.unique_positions)} positions)"
    )
    figure.savefig(out_path)
    return out_path
