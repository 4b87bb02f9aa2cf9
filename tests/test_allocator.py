"""overbound._allocator: the memory settings of the array-heavy commands take effect on Linux/glibc."""

from __future__ import annotations

import platform
import sys

import numpy as np
import pytest

from overbound._allocator import keep_freed_memory


@pytest.mark.skipif(not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
                    reason="mallopt is glibc's")  # fmt: skip
def test_keep_freed_memory_takes_effect_on_glibc():
    before = np._core.multiarray._get_madvise_hugepage()
    try:
        assert keep_freed_memory() is True  # every mallopt call accepted
        assert np._core.multiarray._get_madvise_hugepage() is False
        a = np.ones(8 << 20)  # 64 MB: served, and summed, as before
        assert a.sum() == 8 << 20
    finally:
        np._core.multiarray._set_madvise_hugepage(before)
