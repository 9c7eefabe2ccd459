"""Keep what C code prints to the process's stdout (file descriptor 1) off it.

PyBullet prints ``pybullet build time: ...`` when it is imported and ``argv[0]=`` each time a
client connects, with C ``printf``: below Python's `sys.stdout`, so `contextlib.redirect_stdout`
does not catch it, and when stdout is a pipe C's buffer flushes it at some later point. That
noise (66 + 18 lines per `ci` sweep) would mix into output meant for reading or parsing.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager


def _flush_c_stdout() -> None:
    """Flush C stdio's buffers (``fflush(NULL)``), so buffered text goes where fd 1 points
    now; a no-op where the C library cannot be loaded."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@contextmanager
def stdout_to_devnull() -> Iterator[None]:
    """Point file descriptor 1 at the null device for the block, then restore it.

    Python's and C's buffers are flushed on entry (what was printed before still reaches
    stdout) and C's again before restoring (what the block printed goes to the null device,
    not later to stdout). Process-wide while it lasts: keep the block short (one import or
    one connect). Where fd 1 cannot be duplicated (no stdout at all), the block runs as is.
    """
    try:
        sys.stdout.flush()
    except (AttributeError, OSError, ValueError):
        pass
    _flush_c_stdout()
    try:
        saved = os.dup(1)
    except OSError:
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        _flush_c_stdout()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
