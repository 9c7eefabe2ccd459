"""The PyBullet simulations of the tasks.

Importing this package imports PyBullet once for the process with file descriptors 1 and 2
pointed at the null device (`import_pybullet_quietly`): PyBullet's C module prints a
``pybullet build time: ...`` banner when it is imported, below Python's `sys.stdout` and
`sys.stderr`, which would otherwise reach every command's output and every sweep worker's.
Every module of the package reaches PyBullet through this package, so later ``import
pybullet`` statements find the module imported and print nothing.
"""

from __future__ import annotations

import ctypes
import os
import sys


def _flush_all() -> None:
    """Flush Python's and C stdio's buffers, so what was written before reaches its file."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


def import_pybullet_quietly() -> None:
    """Import PyBullet with file descriptors 1 and 2 on the null device, then restore them
    (nothing else is done: the module is the same as a plain ``import pybullet``). A no-op
    once PyBullet is imported; where the descriptors cannot be duplicated, a plain import."""
    if "pybullet" in sys.modules:
        return
    _flush_all()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        import pybullet  # noqa: F401

        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401
    finally:
        _flush_all()
        for descriptor, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, descriptor)
            os.close(copy)
        os.close(devnull)


import_pybullet_quietly()
