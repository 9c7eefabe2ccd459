"""The machine a result was computed on, as far as it decides the floating-point numbers.

The pinned code and libraries fix the arithmetic up to what the libraries choose at run time
from the CPU: the OpenBLAS kernels (``Haswell``, ``SkylakeX``, ``Zen``, ...) and the SIMD
targets numpy dispatches its loops to. Two machines with the same `numerics_fingerprint`
give the same bits for the same computation; between fingerprints results agree only up to
rounding, which contact physics and training amplify (docs/findings/reproducibility.md).
PyBullet's and the analytic IK's compiled code does not dispatch on the CPU. Every result file
records `machine_info` in its metadata (`distgprl.schema.result_meta`).
"""

from __future__ import annotations

import ctypes
import platform
from functools import lru_cache

__all__ = ["cpu_model", "machine_info", "numerics_fingerprint", "openblas_cores"]

_CORENAME_FUNCTIONS = (
    "scipy_openblas_get_corename64_",
    "scipy_openblas_get_corename",
    "openblas_get_corename64_",
    "openblas_get_corename",
)


def openblas_cores() -> list[str]:
    """The kernel families numpy's and scipy's OpenBLAS libraries, where loaded in this
    process, picked for this CPU, e.g. ``["Haswell"]``; empty where they cannot be asked (not
    Linux, another BLAS). Other packages' own copies (OpenCV bundles one, which picks
    ``Prescott`` on a SkylakeX CPU) do not compute the results and are left out, so the
    answer does not depend on what else was imported first."""
    try:
        with open("/proc/self/maps") as maps:
            libraries = {
                path
                for path in (line.split()[-1] for line in maps)
                if "openblas" in path.lower() and ("numpy" in path or "scipy" in path)
            }
    except OSError:
        return []
    cores = set()
    for path in sorted(libraries):
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _CORENAME_FUNCTIONS:
            function = getattr(library, name, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                cores.add(function().decode())
                break
    return sorted(cores)


def numerics_fingerprint() -> str:
    """OpenBLAS kernels and numpy SIMD targets in use, e.g.
    ``openblas-Haswell_numpy-X86_V3+X86_V4+AVX512_ICL`` (module docstring)."""
    import numpy  # noqa: F401  (loads numpy's OpenBLAS)
    import scipy.linalg  # noqa: F401  (and scipy's: the same name whatever was imported before)

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

        simd = [target for target in __cpu_dispatch__ if __cpu_features__.get(target)]
    except ImportError:  # another numpy layout
        simd = ["unknown"]
    cores = openblas_cores() or ["unknown"]
    return f"openblas-{'+'.join(cores)}_numpy-{'+'.join(simd) or 'baseline'}"


def cpu_model() -> str:
    """The CPU's model name (Linux ``/proc/cpuinfo``; else `platform.processor`)."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


@lru_cache(maxsize=1)
def machine_info() -> dict[str, str]:
    """``{"cpu": model name, "numerics": fingerprint}`` of this machine (cached)."""
    return {"cpu": cpu_model(), "numerics": numerics_fingerprint()}
