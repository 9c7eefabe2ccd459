"""Reference: the HAP prior L_hap as it was before the speed rewrite (issue 29).

A verbatim copy of ``HapPrior`` (distgprl/safety/hap_loss.py at commit 6b92ebb, renamed),
kept only so that `test_hap_loss.py` can check that the vectorised soft-min, neighbour
selection and moving-obstacle filter give the same values and gradients. Not used by the
package.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_loss import HapPriorConfig


class ReferenceHapPrior:
    """Soft-min distance of query positions to the safe subspace C_safe (Eq. hap_compact).

    Neighbour search (no gradient), two modes:

    * ``"grid"`` (default, for a fixed C_safe): a lookup table over the bounding box of C_safe
      grown by ``margin`` with cells of ``resolution``; each cell stores the ``candidates``
      nearest C_safe points of its centre (exact kNN via ``cKDTree`` at construction, ~0.2 s).
      A query takes its cell's candidates (queries outside the box use the nearest cell), the
      distances to them are computed in torch and the k smallest enter the soft-min. With
      ``candidates = k + 4`` this equals the exact kNN for all but ~0.1 % of queries near the
      subspace; where it differs, it swaps a neighbour of near-equal distance (soft-min error
      < 1 mm on a 0.1 m grid). ~4 ms forward + backward for 256 x 20 queries on 2 cores.
    * ``"kdtree"``: exact kNN by ``cKDTree`` per query batch (build ~1 ms, queries ~10 ms for
      5120 points): for a C_safe that changes often (e.g. filtered every step).

    Args:
        c_safe: safe positions, shape (m, 3), m (e.g. ``SafeSubspace.unique_positions`` or the
            EDF-filtered positions). Repeated positions are merged.
        k: neighbours per query (clipped to m).
        temperature: tau, m.
        subtract_offset: see the module docstring.
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
        subtract_offset: bool = True,
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
        self.subtract_offset = subtract_offset
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
    def from_config(cls, c_safe: np.ndarray, config: HapPriorConfig) -> ReferenceHapPrior:
        return cls(
            c_safe,
            config.k,
            config.temperature,
            subtract_offset=config.subtract_offset,
            neighbour_search=config.neighbour_search,
        )

    def set_points(self, c_safe: np.ndarray) -> None:
        """Replace C_safe (m, 3), m (rebuilds the neighbour search structure)."""
        points = np.unique(np.round(np.asarray(c_safe, dtype=float).reshape(-1, 3), 9), axis=0)
        if len(points) == 0:
            raise ValueError("C_safe is empty")
        self.points_numpy = points
        # Component-wise storage: gathers of (n, k) index arrays stay contiguous.
        self._coordinates = [torch.as_tensor(points[:, i], dtype=self.dtype) for i in range(3)]
        self.k = min(self.k_requested, len(points))
        self._tree = cKDTree(points)
        if self.neighbour_search == "grid":
            self._build_table(points)
        self.offset = 0.0
        if self.subtract_offset:
            # b = mean soft-min at the C_safe points themselves (exact neighbours).
            at_points = torch.as_tensor(points, dtype=torch.float64)
            self.offset = float(self._softmin(at_points, self._exact(points)).mean())

    def _build_table(self, points: np.ndarray) -> None:
        count = min(max(self.candidates_requested, self.k), len(points))
        self._lower = points.min(axis=0) - self.margin
        upper = points.max(axis=0) + self.margin
        self._shape = np.maximum(np.ceil((upper - self._lower) / self.resolution), 1).astype(int)
        axes = [np.arange(n) for n in self._shape]
        cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        centres = self._lower + self.resolution * (cells + 0.5)
        _, index = self._tree.query(centres, k=count, workers=-1)
        self._table = np.ascontiguousarray(np.asarray(index, dtype=np.int64).reshape(-1, count))
        # Largest distance from each cell centre to its candidates.
        self._cell_radius = np.linalg.norm(points[self._table] - centres[:, None, :], axis=2).max(1)
        self._strides = np.array([self._shape[1] * self._shape[2], self._shape[2], 1])

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
        cell = np.floor((positions - self._lower) / self.resolution).astype(np.int64)
        np.clip(cell, 0, self._shape - 1, out=cell)
        return torch.from_numpy(self._table[cell @ self._strides])

    def _wide_neighbours(self, positions: np.ndarray) -> np.ndarray:
        """The ``fallback_candidates`` nearest C_safe indices (n, c) of positions (n, 3), exact.

        (Not a lookup table of the cell centres' nearest points: for the few queries that need
        it, the exact search decides which free points enter the soft-min; a table's
        approximation changed the trained policies' numbers.)
        """
        count = min(self.fallback_candidates, len(self.points_numpy))
        _, wide = self._tree.query(positions, k=count)
        return np.asarray(wide, dtype=np.int64).reshape(len(positions), count)

    def _candidate_radius(self, positions: np.ndarray, index: torch.Tensor) -> np.ndarray:
        """An upper bound (n,), m, on the distance from each query to its candidates."""
        if self.neighbour_search == "grid":
            cell = np.floor((positions - self._lower) / self.resolution).astype(np.int64)
            np.clip(cell, 0, self._shape - 1, out=cell)
            flat = cell @ self._strides
            centre = self._lower + self.resolution * (cell + 0.5)
            return np.linalg.norm(positions - centre, axis=1) + self._cell_radius[flat]
        candidates = self.points_numpy[index.numpy()]
        return np.linalg.norm(candidates - positions[:, None, :], axis=2).max(axis=1)

    def _softmin(
        self, x: torch.Tensor, index: torch.Tensor, blocked: np.ndarray | None = None
    ) -> torch.Tensor:
        """-tau log sum_{kNN} exp(-||x - y|| / tau) for x (n, 3) and candidates (n, c): (n,).

        ``blocked`` (n, c), optional: candidates to leave out (each row keeps at least one).
        """
        flat = index.reshape(-1)
        px, py, pz = (  # (n, c) each
            torch.index_select(c.to(x.dtype), 0, flat).view(index.shape) for c in self._coordinates
        )
        dx, dy, dz = x[:, 0:1] - px, x[:, 1:2] - py, x[:, 2:3] - pz
        # Distances recomputed in torch so the gradient reaches x; the epsilon keeps the
        # gradient finite when x coincides with a C_safe point.
        distances = torch.sqrt(dx * dx + dy * dy + dz * dz + 1e-18)
        if blocked is not None:
            distances = distances.masked_fill(torch.from_numpy(blocked), float("inf"))
        if distances.shape[1] > self.k:
            distances, _ = torch.topk(distances, self.k, dim=1, largest=False, sorted=False)
        tau = self.temperature
        return -tau * torch.logsumexp(distances * (-1.0 / tau), dim=1)  # Eq. (hap_compact)

    def per_point(
        self,
        x: torch.Tensor,
        anchors: torch.Tensor | np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> torch.Tensor:
        """Per-query soft-min minus the offset, shape ``x.shape[:-1]``, m.

        With ``moving`` (and the moving obstacles' ``anchors``, shape ``x.shape``, m, one per
        query), the soft-min runs over C_safe without the points the moving obstacles block at
        that query's anchor (DESIGN §4): blocked candidates are left out; a query with fewer
        than k free candidates searches the ``fallback_candidates`` nearest C_safe points
        (`_wide_neighbours`); a query with no free point among those (it lies deep inside the
        obstacles' blocked zone) gets 0, i.e. no pull (:attr:`last_moving_counts` counts such
        queries). In ``"grid"`` mode the free candidates approximate the filtered kNN (they are the
        cell centre's nearest points): the soft-min is within ~2.5 mm of the exact one.
        """
        flat = x.reshape(-1, 3)
        positions = flat.detach().cpu().numpy()
        index = self.neighbours(positions)
        if moving is None:
            return (self._softmin(flat, index) - self.offset).reshape(x.shape[:-1])
        if anchors is None:
            raise ValueError("a moving-obstacle filter needs the obstacles' anchors")
        if isinstance(anchors, torch.Tensor):
            anchors = anchors.detach().cpu().numpy()
        anchors = np.asarray(anchors, dtype=float).reshape(-1, 3)
        if len(anchors) != len(positions):
            raise ValueError(f"{len(anchors)} anchors for {len(positions)} query positions")
        # Only rows whose candidates can reach the obstacles need the test (a cheap bound:
        # candidate-to-query distance <= the row's candidate radius).
        blocked = np.zeros(index.shape, dtype=bool)
        near = np.flatnonzero(
            np.linalg.norm(positions - anchors, axis=1)
            < moving.reach + self._candidate_radius(positions, index)
        )
        if near.size:
            rows_index = index.numpy()[near]
            blocked[near] = moving.blocked(self.points_numpy[rows_index], anchors[near])
        short = (~blocked).sum(axis=1) < self.k
        values = flat.new_zeros(len(flat))
        rows = np.flatnonzero(~short)
        if len(rows):
            part = self._softmin(flat[rows], index[rows], blocked[rows]) - self.offset
            values = values.index_copy(0, torch.from_numpy(rows), part)
        empty = 0
        if short.any():
            rows = np.flatnonzero(short)
            wide = self._wide_neighbours(positions[rows])
            wide_blocked = moving.blocked(self.points_numpy[wide], anchors[rows])
            has_free = ~wide_blocked.all(axis=1)
            empty = int((~has_free).sum())
            if has_free.any():
                keep = rows[has_free]
                part = self._softmin(
                    flat[keep], torch.from_numpy(wide[has_free]), wide_blocked[has_free]
                )
                values = values.index_copy(0, torch.from_numpy(keep), part - self.offset)
        self.last_moving_counts = {
            "queries": len(flat),
            "with_blocked": int(blocked.any(axis=1).sum()),
            "fallback": int(short.sum()),
            "no_free": empty,
        }
        return values.reshape(x.shape[:-1])

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
