"""Truncated path signatures of piecewise-linear paths, and a signature-similarity score.

The signature of a path ``X: [0, 1] -> R^d`` is the sequence of its iterated integrals
(Chen 1958; Lyons 1998). Level ``k`` is the tensor

    S^k_{i1..ik}(X) = ∫_{0<t1<...<tk<1} dX^{i1}_{t1} ... dX^{ik}_{tk},

with ``d^k`` entries. For a straight segment with increment ``Δ`` it is ``Δ^{⊗k} / k!``, and
Chen's identity ``S(X * Y) = S(X) ⊗ S(Y)`` (truncated tensor product, level 0 = 1) gives the
signature of a concatenation. A polyline is a concatenation of straight segments, so the
signatures here are *exact* for the piecewise-linear interpolation of the samples (no
quadrature error). Segments are combined by a pairwise (tree) reduction, ``log2(n)``
vectorised Chen products, which keeps the torch version fast and differentiable.

Layout of a flat signature (shared by every function here): levels ``1..depth``
concatenated, each level flattened in row-major (C) order, so entry ``(i1, ..., ik)`` of level
``k`` sits at offset ``d + ... + d^{k-1} + i1 d^{k-1} + ... + ik``. Level 0 (always 1) is
not stored. Length: ``signature_dimension(d, depth) = d + d^2 + ... + d^depth``.

Properties used by the callers (and tested):

- invariant to translation of the path (only increments enter);
- invariant to reparameterisation (resampling along the same polyline, pauses, speed);
- level 1 is the net displacement; the antisymmetric part of level 2 is the signed (Lévy)
  area swept by the path in each coordinate plane.

Options (both off by default):

- ``time_augment``: append a channel ``τ = linspace(0, 1, n)`` (dimensionless phase) before
  computing the signature. This makes the signature depend on *how fast* the path is
  traversed, not only on its shape; it assumes the samples are evenly spaced in time.
- ``basepoint``: prepend the origin (zero in every channel, including ``τ``) to the path. The
  signature then also sees the absolute start position, so translation invariance is lost.

Units: level ``k`` carries the path's unit to the power ``k`` (e.g. m^k for positions).
Do not mix metres and radians in one path without scaling them (see ``signature_similarity``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
import torch

#: A numpy array or a torch tensor: the signature's algebra is written once for both, each
#: call staying in one of them (a constrained type variable, not a union).
ArrayOrTensor = TypeVar("ArrayOrTensor", np.ndarray, torch.Tensor)


def signature_dimension(channels: int, depth: int) -> int:
    """Length of a flat truncated signature: ``channels + channels**2 + ... + channels**depth``."""
    _check_depth(depth)
    if channels < 1:
        raise ValueError(f"channels must be >= 1, got {channels}")
    return sum(channels**level for level in range(1, depth + 1))


def signature_levels(flat: ArrayOrTensor, channels: int, depth: int) -> list[ArrayOrTensor]:
    """Split flat signatures into their levels as tensors.

    Args:
        flat: shape (..., signature_dimension(channels, depth)), numpy or torch.
        channels: path dimension ``d``.
        depth: truncation depth.

    Returns:
        ``depth`` arrays; entry ``k - 1`` has shape (..., d, ..., d) with ``k`` trailing axes
        of size ``d`` (views of ``flat`` where possible).
    """
    expected = signature_dimension(channels, depth)
    if flat.shape[-1] != expected:
        raise ValueError(
            f"flat signature has {flat.shape[-1]} entries, expected {expected} "
            f"for channels={channels}, depth={depth}"
        )
    levels = []
    offset = 0
    batch_shape = tuple(flat.shape[:-1])
    for level in range(1, depth + 1):
        size = channels**level
        levels.append(flat[..., offset : offset + size].reshape(batch_shape + (channels,) * level))
        offset += size
    return levels


def signature(
    path: np.ndarray,
    depth: int = 3,
    *,
    time_augment: bool = False,
    basepoint: bool = False,
) -> np.ndarray:
    """Truncated signature of the piecewise-linear interpolation of ``path`` (numpy, float64).

    Args:
        path: shape (n, d) or batched (..., n, d); samples of the path in order (any unit,
            e.g. metres). ``n >= 1``; a single point (no segment) has signature 0.
        depth: truncation level (>= 1; GPRL uses >= 2, default 3).
        time_augment: append the phase channel ``linspace(0, 1, n)`` (see module docstring).
        basepoint: prepend the origin to the path (see module docstring).

    Returns:
        shape (..., D) with ``D = signature_dimension(d', depth)``, ``d' = d + time_augment``;
        level ``k`` in units of the path to the power ``k``.
    """
    array = np.asarray(path, dtype=np.float64)
    _check_path_shape(array.shape)
    _check_depth(depth)
    if time_augment:
        phase = np.broadcast_to(
            np.linspace(0.0, 1.0, array.shape[-2])[:, None], array.shape[:-1] + (1,)
        )
        array = np.concatenate([array, phase], axis=-1)
    if basepoint:
        array = np.concatenate([np.zeros_like(array[..., :1, :]), array], axis=-2)
    if array.shape[-2] == 1:
        array = np.concatenate([array, array], axis=-2)  # one point: a zero-length segment
    increments = np.diff(array, axis=-2)
    return _signature_from_increments(
        increments,
        depth,
        concatenate=lambda parts, axis: np.concatenate(parts, axis=axis),
        zeros_like=np.zeros_like,
    )


def signature_torch(
    paths: torch.Tensor,
    depth: int = 3,
    *,
    time_augment: bool = False,
    basepoint: bool = False,
) -> torch.Tensor:
    """Batched, differentiable truncated signature (torch); same maths as :func:`signature`.

    Args:
        paths: shape (B, n, d) (or any (..., n, d)); floating dtype, any device. Gradients
            flow to ``paths``.
        depth: truncation level (>= 1).
        time_augment: append the phase channel ``linspace(0, 1, n)``.
        basepoint: prepend the origin to each path.

    Returns:
        shape (..., D), same dtype and device as ``paths``.
    """
    if not torch.is_tensor(paths) or not torch.is_floating_point(paths):
        raise TypeError("paths must be a floating-point torch.Tensor")
    _check_path_shape(tuple(paths.shape))
    _check_depth(depth)
    if time_augment:
        paths = _append_phase_torch(paths)
    if basepoint:
        paths = torch.cat([torch.zeros_like(paths[..., :1, :]), paths], dim=-2)
    if paths.shape[-2] == 1:
        paths = torch.cat([paths, paths], dim=-2)  # one point: a zero-length segment
    increments = paths[..., 1:, :] - paths[..., :-1, :]
    return _signature_from_increments(
        increments,
        depth,
        concatenate=lambda parts, axis: torch.cat(parts, dim=axis),
        zeros_like=torch.zeros_like,
    )


def signature_distance(
    path_a: np.ndarray,
    path_b: np.ndarray,
    depth: int = 3,
    scale: float | Sequence[float] | np.ndarray = 0.1,
    *,
    time_augment: bool = False,
) -> float:
    """Length-normalised signature distance between two paths, in units of ``scale`` (numpy).

    Definition. Let ``a' = path_a / scale``, ``b' = path_b / scale`` (channel-wise, so both
    are dimensionless) and ``L = (length(a') + length(b')) / 2`` their mean arc length. Then::

        distance = sqrt( Σ_{k=1..depth} ‖S^k(a') − S^k(b')‖² / L^{2(k−1)} )
                 = L · ‖S(a' / L) − S(b' / L)‖₂,

    i.e. the signatures of the two paths rescaled to (mean) unit length are compared, so
    every level is O(1), and the result is multiplied back by ``L``. Consequences:

    - level 1 contributes exactly ``‖Δa − Δb‖ / scale`` (difference of net displacements);
    - a perturbation of size ``ε`` metres changes every level by O(``ε / scale``), so the
      distance is "in metres / scale" for any path length (without the ``L^{k−1}``
      normalisation level ``k`` would grow like ``(length / scale)^k`` and swamp the rest);
    - scaling both paths by ``c`` scales the distance by ``c``; it is translation and
      reparameterisation invariant (signatures are) and 0 iff the truncated signatures agree.

    Args:
        path_a: shape (n_a, d), e.g. adapted tool positions in metres.
        path_b: shape (n_b, d), e.g. demonstrated tool positions in metres (n_b may differ).
        depth: truncation level (>= 1; GPRL uses >= 2, default 3).
        scale: positive length scale, metres (scalar) or per channel, shape (d,) (e.g.
            metres for positions and radians for rotation-vector channels).
        time_augment: compare time-augmented paths (sensitive to the speed profile); the
            phase channel runs from 0 to 1, i.e. it weighs like a displacement of one
            ``scale``.

    Returns:
        The distance (dimensionless, in units of ``scale``), >= 0.
    """
    array_a = np.asarray(path_a, dtype=np.float64)
    array_b = np.asarray(path_b, dtype=np.float64)
    if array_a.ndim != 2 or array_b.ndim != 2 or array_a.shape[1] != array_b.shape[1]:
        raise ValueError(
            f"expected two paths of shapes (n_a, d), (n_b, d), got {array_a.shape}, {array_b.shape}"
        )
    scale_array = _check_scale(scale, array_a.shape[1])
    scaled_a = array_a / scale_array
    scaled_b = array_b / scale_array
    if time_augment:
        scaled_a = np.concatenate([scaled_a, np.linspace(0.0, 1.0, len(scaled_a))[:, None]], 1)
        scaled_b = np.concatenate([scaled_b, np.linspace(0.0, 1.0, len(scaled_b))[:, None]], 1)
    length_a = np.linalg.norm(np.diff(scaled_a, axis=0), axis=1).sum()
    length_b = np.linalg.norm(np.diff(scaled_b, axis=0), axis=1).sum()
    mean_length = max(0.5 * (length_a + length_b), _SMALLEST_LENGTH)
    difference = signature(scaled_a / mean_length, depth) - signature(scaled_b / mean_length, depth)
    return float(mean_length * np.linalg.norm(difference))


def signature_similarity(
    path_a: np.ndarray,
    path_b: np.ndarray,
    depth: int = 3,
    scale: float | Sequence[float] | np.ndarray = 0.1,
    *,
    time_augment: bool = False,
) -> float:
    """Signature similarity in (0, 1] used by the GPRL baseline's reward (numpy).

    Definition: ``similarity = exp(−signature_distance(path_a, path_b, depth, scale))``
    (see :func:`signature_distance` for the length-normalised distance).

    Why this form: it is 1 exactly when the truncated signatures agree (same shape up to
    translation and reparameterisation), decreases monotonically with the distance, never
    reaches 0 (a bounded reward term), and is in physical units through a single length:
    moving the end of a straight path by ``scale`` metres sideways scores about ``exp(−1)``
    at level 1, and the length normalisation keeps the higher levels on the same footing
    whatever the size of the motion. A cosine of raw signatures was rejected: it ignores
    the size of a deviation, mixes m, m² and m³ entries without a common unit, is
    undefined for a motionless path and can be negative.

    Args:
        path_a, path_b: shapes (n_a, d), (n_b, d); sample counts may differ. Pass
            positions (metres) or scale rotation channels with a per-channel ``scale``.
        depth: truncation level (>= 1; GPRL uses >= 2, default 3).
        scale: positive length scale (metres, or per channel (d,)), default 0.1 m.
        time_augment: also compare speed profiles (phase channel, see module docstring).

    Returns:
        Similarity in (0, 1].
    """
    return math.exp(-signature_distance(path_a, path_b, depth, scale, time_augment=time_augment))


def signature_distance_torch(
    paths_a: torch.Tensor,
    paths_b: torch.Tensor,
    depth: int = 3,
    scale: float | Sequence[float] | np.ndarray | torch.Tensor = 0.1,
    *,
    time_augment: bool = False,
) -> torch.Tensor:
    """Batched, differentiable :func:`signature_distance`.

    Args:
        paths_a: shape (..., n_a, d).
        paths_b: shape (..., n_b, d); batch shape broadcastable with that of ``paths_a``.
        depth: truncation level (>= 1).
        scale: positive length scale, scalar or per channel (d,), metres/radians.
        time_augment: compare time-augmented paths.

    Returns:
        Distances >= 0, shape = broadcast batch shape, dtype of ``paths_a``. Gradients are
        finite everywhere (zero-length segments and equal signatures included).
    """
    if paths_a.shape[-1] != paths_b.shape[-1]:
        raise ValueError(f"paths differ in dimension: {paths_a.shape} vs {paths_b.shape}")
    if torch.is_tensor(scale):
        scale = scale.detach().cpu().numpy()
    scale_array = _check_scale(scale, paths_a.shape[-1])
    scale_tensor = torch.as_tensor(scale_array, dtype=paths_a.dtype, device=paths_a.device)
    scaled_a = paths_a / scale_tensor
    scaled_b = paths_b / scale_tensor
    if time_augment:
        scaled_a = _append_phase_torch(scaled_a)
        scaled_b = _append_phase_torch(scaled_b)
    length_a = _safe_norm(scaled_a[..., 1:, :] - scaled_a[..., :-1, :]).sum(dim=-1)
    length_b = _safe_norm(scaled_b[..., 1:, :] - scaled_b[..., :-1, :]).sum(dim=-1)
    mean_length = torch.clamp(0.5 * (length_a + length_b), min=_SMALLEST_LENGTH)[..., None, None]
    difference = signature_torch(scaled_a / mean_length, depth) - signature_torch(
        scaled_b / mean_length, depth
    )
    return mean_length[..., 0, 0] * _safe_norm(difference)


def signature_similarity_torch(
    paths_a: torch.Tensor,
    paths_b: torch.Tensor,
    depth: int = 3,
    scale: float | Sequence[float] | np.ndarray | torch.Tensor = 0.1,
    *,
    time_augment: bool = False,
) -> torch.Tensor:
    """Batched, differentiable :func:`signature_similarity`: ``exp(−signature_distance_torch)``.

    Args and shapes as :func:`signature_distance_torch`; returns similarities in (0, 1].
    """
    return torch.exp(
        -signature_distance_torch(paths_a, paths_b, depth, scale, time_augment=time_augment)
    )


# --------------------------------------------------------------------------------------
# Internals shared by the numpy and torch versions (they use only operators, slicing,
# reshape and the two injected functions, which both libraries provide).


_SMALLEST_LENGTH = 1e-12
"""Floor on the mean path length (in units of ``scale``) so that two motionless paths
(both signatures zero) have distance 0 instead of 0 / 0."""


def _safe_norm(vectors: torch.Tensor) -> torch.Tensor:
    """Euclidean norm over the last axis with gradient 0 (not NaN) at the zero vector."""
    squared = (vectors**2).sum(dim=-1)
    positive = squared > 0
    return torch.where(positive, torch.sqrt(torch.where(positive, squared, 1.0)), 0.0)


def _append_phase_torch(paths: torch.Tensor) -> torch.Tensor:
    """Append the channel ``linspace(0, 1, n)``: (..., n, d) -> (..., n, d + 1)."""
    phase = torch.linspace(0.0, 1.0, paths.shape[-2], dtype=paths.dtype, device=paths.device)
    return torch.cat([paths, phase[:, None].expand(paths.shape[:-1] + (1,))], dim=-1)


def _check_depth(depth: int) -> None:
    if not isinstance(depth, int | np.integer) or depth < 1:
        raise ValueError(f"depth must be an integer >= 1, got {depth!r}")


def _check_path_shape(shape: tuple[int, ...]) -> None:
    if len(shape) < 2:
        raise ValueError(f"path must have shape (..., n, d), got {shape}")
    if shape[-2] < 1 or shape[-1] < 1:
        raise ValueError(f"path needs at least one point and one channel, got {shape}")


def _check_scale(scale: float | Sequence[float] | np.ndarray, channels: int) -> np.ndarray:
    scale_array = np.asarray(scale, dtype=np.float64)
    if scale_array.ndim > 1 or (scale_array.ndim == 1 and scale_array.shape[0] != channels):
        raise ValueError(f"scale must be a scalar or have shape ({channels},), got {scale_array}")
    if not np.all(np.isfinite(scale_array)) or np.any(scale_array <= 0):
        raise ValueError(f"scale must be positive and finite, got {scale_array}")
    return scale_array


def _outer_flat(left: ArrayOrTensor, right: ArrayOrTensor) -> ArrayOrTensor:
    """Flattened outer product of the last axes: (..., p), (..., q) -> (..., p * q)."""
    product = left[..., :, None] * right[..., None, :]
    flat: ArrayOrTensor = product.reshape(tuple(product.shape[:-2]) + (-1,))
    return flat


def _segment_exponentials(increments: ArrayOrTensor, depth: int) -> list[ArrayOrTensor]:
    """Levels of ``exp(Δ) = (Δ, Δ⊗Δ/2!, ..., Δ^{⊗depth}/depth!)`` for each segment.

    Args:
        increments: shape (..., m, d).

    Returns:
        ``depth`` arrays of shapes (..., m, d**k).
    """
    levels = [increments]
    for level in range(2, depth + 1):
        levels.append(_outer_flat(levels[-1], increments) / level)
    return levels


def _chen_product(left: list[ArrayOrTensor], right: list[ArrayOrTensor]) -> list[ArrayOrTensor]:
    """Truncated tensor product of group-like elements (level 0 = 1 implicit).

    ``(left ⊗ right)_k = left_k + right_k + Σ_{i=1}^{k-1} left_i ⊗ right_{k-i}``.
    """
    depth = len(left)
    product = []
    for level in range(1, depth + 1):
        term = left[level - 1] + right[level - 1]
        for left_level in range(1, level):
            term = term + _outer_flat(left[left_level - 1], right[level - left_level - 1])
        product.append(term)
    return product


def _signature_from_increments(
    increments: ArrayOrTensor,
    depth: int,
    concatenate: Callable[[list[ArrayOrTensor], int], ArrayOrTensor],
    zeros_like: Callable[[ArrayOrTensor], ArrayOrTensor],
) -> ArrayOrTensor:
    """Signature of the polyline with the given increments (..., m, d) -> (..., D)."""
    if increments.shape[-2] == 0:
        raise ValueError("a path needs one segment; repeat a single point to get the identity")
    levels = _segment_exponentials(increments, depth)
    # Pairwise reduction preserving segment order (Chen's identity is associative).
    while levels[0].shape[-2] > 1:
        if levels[0].shape[-2] % 2 == 1:
            # Pad with the identity (a zero-length segment) so that every segment has a pair.
            levels = [concatenate([level, zeros_like(level[..., :1, :])], -2) for level in levels]
        earlier = [level[..., 0::2, :] for level in levels]
        later = [level[..., 1::2, :] for level in levels]
        levels = _chen_product(earlier, later)
    return concatenate([level[..., 0, :] for level in levels], -1)
