"""`DistanceField.distance` as NumPy array operations (v7's implementation, verbatim), the
reference of the compiled pass in ``tests/safety/test_edf.py``, and the bound on how far two
correct evaluations of its rules may differ in rounding (`rounding_bounds`)."""

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


# ---------------------------------------------------------------- rounding bounds
UNIT_ROUNDOFF = 2.0**-53  # binary64, round to nearest


def gamma(roundings: int) -> float:
    """Higham's gamma_m = m u / (1 - m u): relative error bound of m successive roundings."""
    return roundings * UNIT_ROUNDOFF / (1.0 - roundings * UNIT_ROUNDOFF)


def coordinate_magnitudes(field, points, dynamic_shift=None):
    """M (3, S, n): per local coordinate, the sum of the magnitudes of the terms it is summed
    from, sum_j |R_jk x_j| + |t_k| (+ sum_j |R_jk shift_j| for a dynamic shape), m."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    homogeneous = np.ones((4, len(points)))
    homogeneous[:3] = np.abs(points).T
    flat = np.abs(field._local_transform) @ homogeneous
    if dynamic_shift is not None and field._dynamic_rows.size:
        rows = field._dynamic_rows
        shift = np.broadcast_to(np.abs(np.asarray(dynamic_shift, float)), points.shape)
        flat[rows] += np.abs(field._rotations_stack[rows]) @ shift.T
    return flat.reshape(3, len(field.names), len(points))


def rounding_bounds(field, points, dynamic_shift=None):
    """How far two correct binary64 evaluations of `DistanceField.distance`'s rules may be
    apart (any summation order of the local coordinates, with or without FMA: plain sums in
    the compiled pass, whatever BLAS kernel in `reference_distance`).

    Per shape s and point, with u = 2^-53, gamma_m = m u / (1 - m u), M_k the term magnitudes
    of local coordinate k (`coordinate_magnitudes`), |M| = ||M||_2 and |h| the norm of the
    half extents that enter a rounding (a cylinder's dummy y extent enters as 0 - h, exactly,
    so it counts 0):

    * local coordinates (a 4-term product, minus a 3-term product for a dynamic shape):
      |dl_k| <= gamma_5 M_k, so ||dl||_2 <= E_l = gamma_5 |M|;
    * excess q = a - h (a cylinder's radial sqrt: 2 more roundings):
      ||dq||_2 <= E_q = gamma_8 (|M| + |h|);
    * the folded-box distance is 1-Lipschitz in q (the signed distance to the orthant
      q <= 0), and its own sqrt of three squares and final sum round 5 more times:
      |dd| <= gamma_13 (|M| + |h|) per evaluation, twice that between two evaluations.

    d is a min over shapes: |min a - min b| <= max(|a_i - b_i|, |a_j - b_j|) over the two
    argmins, both among the shapes within twice the largest bound of the reference's min.

    The gradient of the nearest shape (when the nearest shape, the inside/outside case, the
    nearest face and the sign of its coordinate are the same in both evaluations; NaN where
    rounding could change them) differs by at most, between two evaluations:
    4 E_q / (outside - E_q) outside (the direction of max(q, 0)), plus
    4 E_l / (r - E_l) where a cylinder's radial direction (l_x, l_y) / r is used, plus
    2 gamma_15 (the normalisations and the rotation to the world: 15 roundings of unit-size
    values, |R| = 1).

    Returns:
        d_bound (n,), m, and grad_bound (n,) (per component, NaN where not comparable).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(points)
    columns = np.arange(n)
    c = field._first_cylinder
    size = np.linalg.norm(coordinate_magnitudes(field, points, dynamic_shift), axis=0)  # (S, n)
    half = field._half_extents[..., 0].copy()  # (3, S)
    half[1, c:] = 0.0
    scale = size + np.linalg.norm(half, axis=0)[:, None]
    shape_bounds = 2.0 * gamma(13) * scale
    local, excess, radial = field._excess(points, dynamic_shift)
    per_shape, outside, _, largest = field._signed(excess)
    candidates = per_shape <= per_shape.min(axis=0) + 2.0 * shape_bounds.max(axis=0)
    d_bound = np.where(candidates, shape_bounds, 0.0).max(axis=0)

    nearest = per_shape.argmin(axis=0)
    error_l = gamma(5) * size[nearest, columns]
    error_q = gamma(8) * scale[nearest, columns]
    out = outside[nearest, columns]
    q = excess[:, nearest, columns]  # (3, n)
    ordered = np.sort(q, axis=0)
    face = q.argmax(axis=0)
    is_outside = out > 2.0 * error_q
    is_inside = largest[nearest, columns] < -2.0 * error_q
    is_cylinder = nearest >= c
    # Inside, the gradient is the nearest face's normal: the same face in both evaluations
    # when the two largest excesses are further apart than the errors can move them, and
    # the same side when that face's coordinate is clear of 0 (a cylinder's radial face
    # takes its direction from (l_x, l_y) instead: the radial term).
    face_clear = ordered[2] - ordered[1] > 4.0 * error_q
    radial_face = is_cylinder & (face == 0)
    side_clear = radial_face | (np.abs(local[face, nearest, columns]) > 2.0 * error_l)
    radial_used = np.where(is_outside, is_cylinder & (q[0] > 0.0), radial_face)
    cylinder_index = np.clip(nearest - c, 0, None)
    r = radial[cylinder_index, columns] if radial is not None else np.zeros(n)
    radial_clear = ~radial_used | (r > 2.0 * error_l)
    comparable = candidates.sum(axis=0) == 1
    comparable &= is_outside | (is_inside & face_clear & side_clear)
    comparable &= radial_clear
    with np.errstate(divide="ignore", invalid="ignore"):
        grad_bound = (
            2.0 * gamma(15)
            + np.where(is_outside, 4.0 * error_q / (out - error_q), 0.0)
            + np.where(radial_used, 4.0 * error_l / (r - error_l), 0.0)
        )
    return d_bound, np.where(comparable, grad_bound, np.nan)
