"""Sums of products whose last digit does not depend on the BLAS thread count.

``a @ b`` hands a long dot product to BLAS, which splits it across its threads
(``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``): the partial sums, so the rounding, change
with the thread count, and the JSON with them (issue 13: ``parametric.json`` differed in its
12th digit between 1 and 2 threads). ``np.einsum`` sums with numpy's own single-threaded
loop: the same bytes on any machine setting.
"""

from __future__ import annotations

import numpy as np

__all__ = ["dot", "matvec", "vecmat"]


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``sum_i a_i b_i`` of two 1-D arrays.

    >>> dot(np.array([1.0, 2.0]), np.array([3.0, 4.0]))
    11.0
    """
    return float(np.einsum("i,i->", a, b))


def matvec(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``m @ v`` for a 2-D ``m`` and a 1-D ``v`` (``sum_j m_ij v_j``)."""
    return np.einsum("ij,j->i", m, v)


def vecmat(v: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``v @ m`` for a 1-D ``v`` and a 2-D ``m`` (``sum_i v_i m_ij``)."""
    return np.einsum("i,ij->j", v, m)
