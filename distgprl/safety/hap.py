"""HAP safe subspace C_safe (paper §IV-B; Sukkar et al., T-RO 2025; DESIGN §4): the public names.

The implementation is split by concern; import from here or from the part:

- :mod:`distgprl.safety.hap_build`: the algorithm (`HapConfig`, `build_subspace`,
  `SafeSubspace`, `HapBuildStats`, a tqdm progress reporter);
- :mod:`distgprl.safety.hap_cache`: the cache key, the ``.npz`` file and `build_or_load`;
- :mod:`distgprl.safety.hap_filter`: moving obstacles (`filter_with_edf`, `safe_mask`,
  `MovingObstacleFilter`) and `tool_bounds`;
- :mod:`distgprl.safety.hap_plot`: `plot_subspace`.
"""

from __future__ import annotations

from distgprl.safety.hap_build import (
    ALGORITHM_VERSION,
    HapBuildStats,
    HapConfig,
    SafeSubspace,
    build_subspace,
    tqdm_progress,
)
from distgprl.safety.hap_cache import (
    build_or_load,
    load_subspace,
    save_subspace,
    subspace_cache_key,
)
from distgprl.safety.hap_filter import MovingObstacleFilter, filter_with_edf, safe_mask, tool_bounds
from distgprl.safety.hap_plot import plot_subspace

__all__ = [
    "ALGORITHM_VERSION",
    "HapBuildStats",
    "HapConfig",
    "MovingObstacleFilter",
    "SafeSubspace",
    "build_or_load",
    "build_subspace",
    "filter_with_edf",
    "load_subspace",
    "plot_subspace",
    "safe_mask",
    "save_subspace",
    "subspace_cache_key",
    "tool_bounds",
    "tqdm_progress",
]
