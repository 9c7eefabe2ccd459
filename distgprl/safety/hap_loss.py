"""The HAP safe-subspace prior L_hap (paper Eq. hap_compact, §IV-B), in torch.

    L_hap = 1/N_q sum_q  -tau log sum_{y in kNN(x_q)} exp(-||x_q - y|| / tau)

for N_q positions x_q sampled along the adapted trajectory and the k nearest points y of C_safe,
as the equation is written: the raw soft-min in metres, no offset, no hinge.
The neighbour search runs without gradients (a precomputed lookup table or scipy ``cKDTree``,
see :class:`HapPrior`); the distances to the found neighbours, the soft-min and its gradient
w.r.t. x_q (sum_j w_j (x_q - y_j) / ||x_q - y_j||, w = softmax(-d / tau) over the kNN) are
computed together in compiled loops (`distgprl.safety.hap_kernels`), vectorised over all
queries, and handed to autograd as one node, so the gradient reaches x_q (and through the
linear GP maps the actor's sampled actions).

The raw soft-min is at most the nearest distance, ``softmin <= min_y ||x - y||``, and is
negative on and near C_safe (at a C_safe point the other neighbours, one grid step away, still
contribute): a constant shift would change no gradient, only the reported value, so none is
subtracted. ``hinge_step`` gives a variant (hinged at a safe cell's largest
soft-min and divided by the grid step, `SACConfig.hap_hinge`) for configurations that ask for
it; it is not the paper's equation.

Defaults (the paper leaves them open):
    * ``k = 8``: on a 0.1 m grid, a point's 8 nearest C_safe points span the surrounding cell
      (its up to 8 corners), so the soft-min interpolates smoothly between grid points instead
      of snapping to the nearest one, while far-away parts of C_safe do not dilute it.
    * ``tau = 0.05`` m: half the grid step. Neighbours further than ~tau beyond the nearest one
      are weighted by < e^-1, so the loss tracks the nearest-point distance (the prior's
      meaning) while staying smooth across Voronoi boundaries of the grid.
    * ``N_q = 20`` query positions per trajectory (:data:`DEFAULT_QUERY_POINTS`, used by the
      caller that samples the trajectory): about one per 5 % of the motion, more than the 15
      via-points, so segments between via-points are covered.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch.autograd.function import BackwardCFunction, FunctionCtx

from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_kernels import (
    GridTable,
    grid_candidates,
    grid_softmin,
    softmin_with_gradient,
)

__all__ = ["DEFAULT_QUERY_POINTS", "HapPrior", "HapPriorConfig"]

DEFAULT_QUERY_POINTS = 20

#: What `ValueWithGradient` calls in its forward: () -> (values, gradient).
Evaluate = Callable[[], tuple[torch.Tensor, torch.Tensor]]


class ValueWithGradient(torch.autograd.Function):
    """Values whose gradient w.r.t. ``x`` was computed with them, without autograd.

    ``ValueWithGradient.apply(x, evaluate)``: ``evaluate()`` returns (values, gradient), the
    values of any shape V and the gradient of each value w.r.t. its own slice of ``x``, of
    shape V + S (e.g. a scalar and d value / d x of x's shape; or per-query values (n,) and a
    jacobian (n, 3) w.r.t. queries x (n, 3)); backward is one broadcast product.
    """

    @staticmethod
    def forward(ctx: FunctionCtx, x: torch.Tensor, evaluate: Evaluate) -> torch.Tensor:
        values, gradient = evaluate()
        ctx.save_for_backward(gradient)
        return values

    @staticmethod
    def backward(ctx: BackwardCFunction, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (gradient,) = ctx.saved_tensors
        extra = gradient.dim() - grad.dim()
        return grad.reshape(*grad.shape, *([1] * extra)) * gradient, None

    @classmethod
    def of(cls, x: torch.Tensor, evaluate: Evaluate) -> torch.Tensor:
        """``apply(x, evaluate)``, typed."""
        # torch declares `Function.apply(cls, *args, **kwargs)` without annotations
        values: torch.Tensor = cls.apply(x, evaluate)  # type: ignore[no-untyped-call]
        return values


@dataclass(frozen=True)
class HapPriorConfig:
    """Parameters of L_hap (module docstring justifies the defaults).

    Attributes:
        k: neighbours in the soft-min.
        temperature: soft-min temperature tau, m.
        query_points: positions N_q sampled along each trajectory (used by the caller).
        neighbour_search: ``"grid"`` (fixed C_safe, fastest) or ``"kdtree"`` (see HapPrior).
    """

    k: int = 8
    temperature: float = 0.05
    query_points: int = DEFAULT_QUERY_POINTS
    neighbour_search: str = "grid"


def interior_softmin_bound(step: float, temperature: float, k: int, samples: int = 21) -> float:
    """The largest soft-min (Eq. hap_compact, k nearest points) of any position inside an
    unbounded, fully safe cubic grid of spacing ``step`` (m): the maximum over a
    ``samples``^3 lattice of positions in one cell, with the exact k nearest nodes of the
    surrounding 6^3 nodes. (The cell's centre is not the maximum: with k = 8 the face
    centres' soft-min exceeds it by 0.04 of a step.) The hinge of ``hinge_step``."""
    axis = (np.arange(6) - 2.0) * step
    nodes = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    cell = np.linspace(0.0, step, samples)
    queries = np.stack(np.meshgrid(cell, cell, cell, indexing="ij"), axis=-1).reshape(-1, 3)
    distances = np.sort(np.linalg.norm(queries[:, None] - nodes[None], axis=-1), axis=1)[:, :k]
    values = -temperature * np.log(np.exp(-distances / temperature).sum(axis=1))
    return float(values.max())


class HapPrior:
    """Soft-min distance of query positions to the safe subspace C_safe (Eq. hap_compact).

    Neighbour search (no gradient), two modes:

    * ``"grid"`` (default, for a fixed C_safe): a lookup table over the bounding box of C_safe
      grown by ``margin`` with cells of ``resolution``; each cell stores the ``candidates``
      nearest C_safe points of its centre (exact kNN via ``cKDTree`` at construction, ~0.2 s).
      A query takes its cell's candidates (queries outside the box use the nearest cell), the
      distances to them are computed and the k smallest enter the soft-min (with the
      moving-obstacle box test, in one compiled pass: `hap_kernels.grid_softmin`). With
      ``candidates = k + 4`` this equals the exact kNN for all but ~0.1 % of queries near the
      subspace; where it differs, it swaps a neighbour of near-equal distance (soft-min error
      < 1 mm on a 0.1 m grid). ~1 ms value + gradient for 256 x 20 queries, one core.
    * ``"kdtree"``: exact kNN by ``cKDTree`` per query batch (build ~1 ms, queries ~10 ms for
      5120 points): for a C_safe that changes often (e.g. filtered every step).

    Args:
        c_safe: safe positions, shape (m, 3), m (e.g. ``SafeSubspace.unique_positions`` or the
            EDF-filtered positions). Repeated positions are merged.
        k: neighbours per query (clipped to m).
        temperature: tau, m.
        hinge_step: 0 (default): Eq. hap_compact as written, the soft-min in m. > 0
            (a variant, the HAP grid step h, m): each query's value is
            max(0, softmin - c) / h with c = `interior_softmin_bound`, the largest soft-min
            anywhere inside a fully safe grid, so the prior is 0 and pulls nowhere inside
            C_safe and about 1 a grid step outside it (dimensionless).
        neighbour_search: ``"grid"`` or ``"kdtree"``.
        resolution: lookup cell size, m (grid mode).
        margin: the lookup box extends this far beyond C_safe, m (grid mode).
        candidates: candidates stored per lookup cell (grid mode), >= k.
        fallback_candidates: exact neighbours searched for a query whose candidates the
            moving-obstacle filter leaves fewer than k of (see :meth:`per_point`).
        dtype: torch dtype of the stored points (float32 to match the networks).
    """

    def __init__(
        self,
        c_safe: np.ndarray,
        k: int = 8,
        temperature: float = 0.05,
        *,
        hinge_step: float = 0.0,
        grid_step: float = 0.0,
        neighbour_search: str = "grid",
        resolution: float = 0.025,
        margin: float = 0.2,
        candidates: int | None = None,
        fallback_candidates: int = 64,
        dtype: torch.dtype = torch.float32,
    ) -> None:
        if temperature <= 0:
            raise ValueError("temperature must be positive")
        if neighbour_search not in ("grid", "kdtree"):
            raise ValueError(f"neighbour_search must be 'grid' or 'kdtree', got {neighbour_search}")
        self.k_requested = int(k)
        self.temperature = float(temperature)
        if hinge_step < 0:
            raise ValueError("hinge_step must be >= 0")
        self.hinge_step = float(hinge_step)
        if grid_step < 0:
            raise ValueError("grid_step must be >= 0")
        self.grid_step = float(grid_step or hinge_step)
        self.neighbour_search = neighbour_search
        self.resolution = float(resolution)
        self.margin = float(margin)
        self.candidates_requested = (
            int(candidates) if candidates is not None else self.k_requested + 4
        )
        self.dtype = dtype
        self.fallback_candidates = int(fallback_candidates)
        self.last_moving_counts: dict[str, int] = {}
        self.set_points(c_safe)

    @classmethod
    def from_config(cls, c_safe: np.ndarray, config: HapPriorConfig) -> HapPrior:
        return cls(
            c_safe,
            config.k,
            config.temperature,
            neighbour_search=config.neighbour_search,
        )

    def set_points(self, c_safe: np.ndarray) -> None:
        """Replace C_safe (m, 3), m (rebuilds the neighbour search structure)."""
        points = np.unique(np.round(np.asarray(c_safe, dtype=float).reshape(-1, 3), 9), axis=0)
        if len(points) == 0:
            raise ValueError("C_safe is empty")
        self.points_numpy = points
        # One row per axis (3, m), in the stored dtype (float32 to match the networks), and
        # its casts to other query dtypes (`_coordinates_as`).
        stored = np.ascontiguousarray(points.T).astype(
            torch.empty((), dtype=self.dtype).numpy().dtype
        )
        self._coordinates_numpy: dict[np.dtype, np.ndarray] = {stored.dtype: stored}
        self.k = min(self.k_requested, len(points))
        self.__dict__.pop("outside_threshold", None)  # depends on k: recomputed when read
        self._tree = cKDTree(points)
        if self.neighbour_search == "grid":
            self._build_table(points)
        # the hinge's c (the largest soft-min inside a fully safe grid); 0: as written
        self.offset = 0.0
        if self.hinge_step > 0:
            self.offset = interior_softmin_bound(self.hinge_step, self.temperature, self.k)

    def _build_table(self, points: np.ndarray) -> None:
        count = min(max(self.candidates_requested, self.k), len(points))
        self._lower = points.min(axis=0) - self.margin
        upper = points.max(axis=0) + self.margin
        self._shape = np.maximum(np.ceil((upper - self._lower) / self.resolution), 1).astype(int)
        axes = [np.arange(n) for n in self._shape]
        cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        centres = self._lower + self.resolution * (cells + 0.5)
        _, index = self._tree.query(centres, k=count, workers=-1)
        index = np.asarray(index, dtype=np.int64).reshape(-1, count)
        # Stored in the smallest integer type that holds the indices: a batch's lookups hit
        # random cells, so a compact table keeps them in cache (int16 for C_safe < 32768).
        small = np.int16 if len(points) <= np.iinfo(np.int16).max else np.int32
        self._table = np.ascontiguousarray(index.astype(small))
        self._grid = GridTable(self._lower, self.resolution, self._shape, self._table)

    def _exact(self, positions: np.ndarray) -> torch.Tensor:
        _, index = self._tree.query(positions, k=self.k, workers=-1)
        return torch.from_numpy(np.asarray(index, dtype=np.int64).reshape(len(positions), self.k))

    def neighbours(self, positions: np.ndarray) -> torch.Tensor:
        """Candidate C_safe indices, shape (n, c) with c >= k, for positions (n, 3) (no grad).

        ``"kdtree"``: exactly the k nearest. ``"grid"``: the lookup cell's candidates, of which
        the soft-min keeps the k nearest.
        """
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        if self.neighbour_search == "kdtree":
            return self._exact(positions)
        return torch.from_numpy(self._grid_candidates(positions).astype(np.int64))

    def _grid_candidates(self, positions: np.ndarray) -> np.ndarray:
        """The lookup cells' candidates (n, c) of positions (n, 3), m (float64): the cell
        containing each position, clipped to the table (grid mode)."""
        return grid_candidates(
            np.ascontiguousarray(positions, dtype=float),
            self._lower,
            self.resolution,
            self._shape,
            self._table,
        )

    def _wide_neighbours(self, positions: np.ndarray) -> np.ndarray:
        """The ``fallback_candidates`` nearest C_safe indices (n, c) of positions (n, 3), exact.

        (Not a lookup table of the cell centres' nearest points: for the few queries that need
        it, the exact search decides which free points enter the soft-min; a table's
        approximation changed the trained policies' numbers.)
        """
        count = min(self.fallback_candidates, len(self.points_numpy))
        _, wide = self._tree.query(positions, k=count)
        return np.asarray(wide, dtype=np.int64).reshape(len(positions), count)

    def _coordinates_as(self, dtype: np.dtype) -> np.ndarray:
        """The stored C_safe coordinates, one row per axis (3, m), cast to ``dtype`` (cached)."""
        arrays = self._coordinates_numpy.get(np.dtype(dtype))
        if arrays is None:
            stored = next(iter(self._coordinates_numpy.values()))  # the first: stored dtype
            arrays = self._coordinates_numpy[np.dtype(dtype)] = stored.astype(dtype)
        return arrays

    def _softmin_values(
        self, x: np.ndarray, index: np.ndarray, blocked: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Soft-min (n,) over the k nearest free candidates and its gradient (n, 3) w.r.t. x.

        x (n, 3), m, and the result in x's dtype (C_safe cast to it); index (n, c) candidates;
        blocked (n, c) or None. Distances sqrt(|x - y|^2 + 1e-18) (as the autograd version
        computed them); the k smallest are kept (where distances tie, the earlier candidate);
        the gradient is sum_j w_j (x - y_j) / d_j with w = softmax(-d / tau) over the kept
        neighbours (`distgprl.safety.hap_kernels.softmin_with_gradient`, compiled loops).
        """
        return softmin_with_gradient(
            x, self._coordinates_as(x.dtype), index, blocked, self.k, self.temperature
        )

    def per_point(
        self,
        x: torch.Tensor,
        anchors: torch.Tensor | np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> torch.Tensor:
        """Per-query soft-min (Eq. hap_compact's summand; with ``hinge_step`` hinged), shape
        ``x.shape[:-1]``, m.

        With ``moving`` (and the moving obstacles' ``anchors``, shape ``x.shape``, m, one per
        query), the soft-min runs over C_safe without the points the moving obstacles block at
        that query's anchor (DESIGN §4): blocked candidates are left out; a query with fewer
        than k free candidates searches the ``fallback_candidates`` nearest C_safe points
        (`_wide_neighbours`); a query with no free point among those (it lies deep inside the
        obstacles' blocked zone) gets 0, i.e. no pull (:attr:`last_moving_counts` counts such
        queries). In ``"grid"`` mode the free candidates approximate the filtered kNN (they are the
        cell centre's nearest points): the soft-min is within ~2.5 mm of the exact one.
        The gradient w.r.t. x is computed with the values (`values_and_gradient`).
        """
        flat = x.reshape(-1, 3)
        if isinstance(anchors, torch.Tensor):
            anchors = anchors.detach().cpu().numpy()

        def evaluate() -> tuple[torch.Tensor, torch.Tensor]:
            values, jacobian = self.values_and_gradient(
                flat.detach().cpu().numpy(), anchors, moving
            )
            return torch.from_numpy(values).to(x.device), torch.from_numpy(jacobian).to(x.device)

        return ValueWithGradient.of(flat, evaluate).reshape(x.shape[:-1])

    @cached_property
    def outside_threshold(self) -> float | None:
        """The value above which a query lies outside C_safe, in `values_and_gradient`'s unit:
        0 with the hinge; for the raw soft-min, the largest soft-min anywhere inside a fully
        safe grid of step ``grid_step`` (`interior_softmin_bound`), None without a grid step.
        Reporting only (the mechanism table's ``hap_active_fraction``); the loss never reads
        it."""
        if self.hinge_step > 0:
            return 0.0
        if self.grid_step <= 0:
            return None
        return interior_softmin_bound(self.grid_step, self.temperature, self.k)

    def values_and_gradient(
        self,
        x: np.ndarray,
        anchors: np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """`per_point` without torch: values (n,), m, and each value's gradient w.r.t. its own
        query (n, 3), for queries x (n, 3), m, computed in x's dtype (NumPy, no autograd).
        With ``hinge_step``: max(0, softmin - c) / h and its gradient."""
        values, jacobian = self._softmin_and_gradient(x, anchors, moving)
        if self.hinge_step <= 0:
            return values, jacobian
        values -= self.offset  # (rows without a free point stay 0: inactive either way)
        active = values > 0
        scale = np.asarray(1.0 / self.hinge_step, dtype=values.dtype)
        hinged = np.where(active, values * scale, np.zeros((), dtype=values.dtype))
        gradient = np.where(active[:, None], jacobian * scale, np.zeros((), dtype=jacobian.dtype))
        return hinged.astype(values.dtype), gradient.astype(jacobian.dtype)

    def _softmin_and_gradient(
        self,
        x: np.ndarray,
        anchors: np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The soft-min (n,) and its gradient (n, 3) in x's dtype, over C_safe without the
        points ``moving`` blocks at each query's anchor; 0 for a query without a free point
        (`values_and_gradient` before the hinge)."""
        x = x.reshape(-1, 3)
        if moving is not None:
            if anchors is None:
                raise ValueError("a moving-obstacle filter needs the obstacles' anchors")
            anchors = np.asarray(anchors).reshape(-1, 3)
            if len(anchors) != len(x):
                raise ValueError(f"{len(anchors)} anchors for {len(x)} query positions")
        if self.neighbour_search == "grid":
            values, jacobian, counts, short = grid_softmin(
                x,
                self._grid,
                self._coordinates_as(x.dtype),
                self.points_numpy,
                anchors if moving is not None else None,
                moving.boxes if moving is not None else None,
                self.k,
                self.temperature,
            )
        else:
            values, jacobian, counts, short = self._exact_softmin(x, anchors, moving)
        if moving is None:
            return values, jacobian
        rows = np.flatnonzero(short)
        assert anchors is not None  # checked above wherever a filter is given
        no_free = self._fall_back(x, anchors, moving, rows, values, jacobian) if rows.size else 0
        self.last_moving_counts = {
            "queries": len(x),
            "with_blocked": int(np.count_nonzero(counts)),
            "fallback": int(rows.size),
            "no_free": no_free,
        }
        return values, jacobian

    def _exact_softmin(
        self,
        x: np.ndarray,
        anchors: np.ndarray | None,
        moving: MovingObstacleFilter | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``"kdtree"`` mode: `grid_softmin`'s four results with the exact k nearest points
        as the candidates (short rows 0)."""
        positions = np.asarray(x, dtype=float)
        index = self._exact(positions).numpy()
        if moving is None:
            values, jacobian = self._softmin_values(x, index, None)
            nothing = np.zeros(len(x), dtype=np.int64)
            return values, jacobian, nothing, nothing.astype(bool)
        assert anchors is not None  # `_softmin_and_gradient` checks it with a filter
        blocked, counts = moving.blocked_candidates(self.points_numpy, index, anchors)
        short = counts > index.shape[1] - self.k
        values = np.zeros(len(x), dtype=x.dtype)
        jacobian = np.zeros((len(x), 3), dtype=x.dtype)
        full = np.flatnonzero(~short)
        if full.size:
            values[full], jacobian[full] = self._softmin_values(x[full], index[full], blocked[full])
        return values, jacobian, counts, short

    def _fall_back(
        self,
        x: np.ndarray,
        anchors: np.ndarray,
        moving: MovingObstacleFilter,
        rows: np.ndarray,
        values: np.ndarray,
        jacobian: np.ndarray,
    ) -> int:
        """The soft-min of the queries ``rows`` (fewer than k free candidates) over their
        ``fallback_candidates`` exact nearest points without the blocked ones, written into
        ``values`` and ``jacobian``; the rows without any free point among those stay 0 (no
        pull). Returns how many those are."""
        wide = self._wide_neighbours(np.asarray(x[rows], dtype=float))
        wide_blocked, _ = moving.blocked_candidates(
            self.points_numpy, wide, np.asarray(anchors[rows], dtype=float)
        )
        free = ~wide_blocked.all(axis=1)
        keep = rows[free]
        if keep.size:
            part, grad = self._softmin_values(x[keep], wide[free], wide_blocked[free])
            values[keep], jacobian[keep] = part, grad
        return int((~free).sum())

    def loss(
        self,
        x: torch.Tensor,
        anchors: torch.Tensor | np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> torch.Tensor:
        """L_hap (Eq. hap_compact): mean over all query points, a scalar tensor, m.

        Args:
            x: query positions, shape (B, N_q, 3) (any leading shape), m; gradients flow to x.
            anchors, moving: optional moving-obstacle filter of C_safe (see :meth:`per_point`).
        """
        return self.per_point(x, anchors, moving).mean()

    __call__ = loss
