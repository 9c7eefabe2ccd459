"""Arithmetic that gives the same bits on every x86-64 CPU (protocol rule 7).

Two of numpy's paths pick their code from the CPU at run time, and the last digits differ
between the choices: matrix products and LAPACK (OpenBLAS' kernel families, e.g. ``Haswell``
on AVX2 and ``SkylakeX`` on AVX-512: ``np.linalg.inv`` of a 15 x 15 kernel matrix differs by
up to a few ulp) and numpy's own SIMD loops for transcendental functions (``np.exp`` on an
AVX-512 CPU differs from AVX2's in about 5 % of the elements, by one ulp). Elementwise
``+ - * /`` are correctly rounded IEEE operations whatever loop computes them.

So the correlation operator S = K (K + λI)⁻¹ (Eq. global_S), which sets the action layout, the
action scales and every reach reported, is built here from those operations only:
`kernel_matrix` evaluates the SE kernel with the C library's ``exp`` (``math.exp``; glibc picks
one implementation on every CPU with FMA, i.e. every AVX2 and AVX-512 CPU) and `spd_inverse`
inverts by Gauss-Jordan elimination written as elementwise row operations (no BLAS, no
LAPACK). Given the committed skill's numbers (`distgprl.skill.committed`), S is then the
same on every machine (tested under both OpenBLAS kernels and with numpy's AVX-512 loops
disabled, tests/skill/test_committed.py).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["correlation_operator", "kernel_matrix", "spd_inverse"]

_EXP = np.frompyfunc(math.exp, 1, 1)


def kernel_matrix(times: np.ndarray, length_scale: float, variance: float = 1.0) -> np.ndarray:
    """σ² exp(-(a - b)² / (2 ℓ²)) over ``times`` (n,), shape (n, n), with ``math.exp``."""
    times = np.asarray(times, dtype=float)
    diff = times[:, None] - times[None, :]
    exponent = -0.5 * (diff / length_scale) ** 2
    values: np.ndarray = variance * _EXP(exponent).astype(float)
    return values


def spd_inverse(matrix: np.ndarray) -> np.ndarray:
    """The inverse of a symmetric positive-definite matrix (n, n) by Gauss-Jordan elimination
    without pivoting (stable for positive-definite matrices), in elementwise operations only.

    Raises:
        ValueError: if a pivot is not positive (the matrix is not positive definite).
    """
    a = np.asarray(matrix, dtype=float)
    n = a.shape[0]
    if a.shape != (n, n):
        raise ValueError(f"expected a square matrix, got shape {a.shape}")
    work = np.concatenate([a, np.eye(n)], axis=1)
    for i in range(n):
        pivot = work[i, i]
        if not pivot > 0.0:
            raise ValueError(f"matrix is not positive definite (pivot {i} is {pivot})")
        work[i] = work[i] / pivot
        column = work[:, i].copy()
        column[i] = 0.0
        work = work - column[:, None] * work[i][None, :]
    inverse: np.ndarray = work[:, n:]
    return inverse


def correlation_operator(kernel: np.ndarray, correlation_lambda: float) -> np.ndarray:
    """S = K (K + λI)⁻¹ = I - λ (K + λI)⁻¹ for a kernel matrix K (n, n), symmetrised
    (Eq. global_S); eigenvalues μ / (μ + λ) in (0, 1).

    Raises:
        ValueError: if ``correlation_lambda`` is not positive.
    """
    if not correlation_lambda > 0:
        raise ValueError("correlation_lambda must be > 0")
    n = kernel.shape[0]
    s = np.eye(n) - correlation_lambda * spd_inverse(kernel + correlation_lambda * np.eye(n))
    symmetric: np.ndarray = 0.5 * (s + s.T)
    return symmetric
