"""`DistanceField.distance` as NumPy array operations (v7's implementation, verbatim), the
reference of the compiled pass in ``tests/safety/test_edf.py``."""

from __future__ import annotations

import numpy as np

_TINY = 1e-12


def reference_distance(field, points, dynamic_shift=None):
    """v7's `DistanceField.distance` on ``field``: (d (n,), grad (n, 3))."""
    self = field
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(points)
    if not self._names:
        return np.full(n, np.inf), np.zeros((n, 3))
    local, excess, radial = self._excess(points, dynamic_shift)
    per_shape, outside, positive, largest = self._signed(excess)
    columns = np.arange(n)
    nearest = per_shape.argmin(axis=0)
    d = per_shape[nearest, columns]

    # Folded gradient of every shape, (3, S, n): max(q, 0) / ||max(q, 0)|| outside; inside
    # (outside part 0) the unit vector of the largest excess component (nearest face).
    # Computed for all shapes at once (a few whole-array operations are cheaper than
    # gathering the nearest shape per point), then masked to the nearest shape.
    grad_local = positive
    grad_local /= np.maximum(outside, _TINY)
    touching = d.min() <= 0.0
    if touching:
        grad_local += (excess == largest) & (outside == 0.0)
    # Unfold: signs of the local coordinates (boxes, planes) or the radial direction
    # (cylinders: the folded x component is the radial one).
    np.copysign(grad_local, local, out=grad_local)
    c = self._first_cylinder
    if radial is not None:
        radial_weight = grad_local[0, c:]
        np.abs(radial_weight, out=radial_weight)
        radial_weight /= np.maximum(radial, _TINY)
        grad_local[1, c:] = radial_weight * local[1, c:]
        radial_weight *= local[0, c:]
    one_hot = np.zeros(per_shape.shape)
    one_hot[nearest, columns] = 1.0
    grad_local *= one_hot
    # World gradient R_j g_local of the nearest shape j: one product with the stacked rows
    # (R_s[:, k])^T, the other shapes being masked to zero.
    grad = grad_local.reshape(-1, n).T @ self._rotations_stack
    if touching:  # exact ties between faces (e.g. a box centre) would sum two normals
        grad /= np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), _TINY)
    return d, grad
