"""Process memory settings for the commands that make many large, short-lived numpy arrays.

The SBAS engine works on whole columns: a day at 1 Hz is some 850,000 satellite rows, and every
step allocates and frees arrays of 7-30 MB. Two Linux defaults make each of those allocations
touch fresh pages, whose faults cost as much as the arithmetic on this project's 2-core VM:

* glibc serves blocks above its mmap threshold (128 kB, raised dynamically up to 32 MB) with a
  fresh ``mmap`` and returns them with ``munmap`` on free, and trims the heap top above 128 kB;
* numpy asks for transparent huge pages on large arrays (``madvise``), and with the common
  ``defrag=madvise`` kernel setting a fault then compacts memory synchronously.

:func:`keep_freed_memory` raises the thresholds so that freed blocks are reused (mmap above
256 MiB only, trim above 1 GiB, 256 MiB of top pad) and turns numpy's huge-page advice off. On
``overbound sbas`` for 24 h of 1 Hz observations (``bench/bench_sbas.py``) system time fell from
2.1-3.2 s to 1.0 s and the whole command from 7.3-7.9 s to 6.2 s, with the peak RSS 1.12 -> 1.19 GB.
Numbers are unchanged: only where memory comes from changes.
"""

from __future__ import annotations

import ctypes
import sys

import numpy as np

__all__ = ["keep_freed_memory", "release_freed_memory"]

# mallopt parameters of glibc's malloc.h
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
_SETTINGS = ((_M_MMAP_THRESHOLD, 256 << 20), (_M_TRIM_THRESHOLD, 1 << 30), (_M_TOP_PAD, 256 << 20))


def keep_freed_memory() -> bool:
    """Keep freed heap memory for reuse and skip numpy's huge-page advice; True if glibc took it.

    Elsewhere than Linux/glibc nothing is changed (and False is returned).
    """
    global _DONE
    if _DONE is not None:
        return _DONE
    _DONE = _apply()
    return _DONE


_DONE: bool | None = None


def _apply() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    madvise = getattr(np._core.multiarray, "_set_madvise_hugepage", None)  # numpy >= 1.20
    if madvise is not None:
        madvise(False)
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # musl and other C libraries: no mallopt
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(mallopt(param, value) == 1 for param, value in _SETTINGS)


def release_freed_memory() -> bool:
    """Give the heap memory freed so far back to the system (glibc's ``malloc_trim``); True if
    some was. For a process that kept it (:func:`keep_freed_memory`) and now waits: the workers of
    a campaign between its passes and the driver's own work."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes, trim.restype = (ctypes.c_size_t,), ctypes.c_int
    return bool(trim(0))
