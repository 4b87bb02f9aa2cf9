r"""Dependence between samples: selecting samples far enough apart in time to be independent.

The position errors of an SBAS receiver are correlated over minutes (ionosphere,
slow corrections). Methods that assume independent samples thin the epochs so that
any two samples kept are at least a *spacing* apart: 360 s for EGNOS (Comby et al.
2003, section I.2, eq. (7): one independent sample per approach).
"""

from __future__ import annotations

import numpy as np

__all__ = ["select_spaced"]


def _validate_select_spaced(time_s: np.ndarray, anchor: int, spacing: float) -> tuple[np.ndarray, int]:
    t = np.asarray(time_s)
    if t.ndim != 1:
        raise ValueError(f"time_s must be one-dimensional, got shape {t.shape}")
    if not (np.issubdtype(t.dtype, np.integer) or np.issubdtype(t.dtype, np.floating)):
        raise ValueError(f"time_s must be numeric, got dtype {t.dtype}")
    if t.size == 0:
        raise ValueError("time_s is empty: there is no anchor to select")
    if np.issubdtype(t.dtype, np.floating) and not np.all(np.isfinite(t)):
        raise ValueError("time_s must be finite")
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        raise ValueError("time_s must be sorted in non-decreasing order")
    a = int(anchor)
    if a != anchor or not 0 <= a < t.size:
        raise ValueError(f"anchor must be an index into time_s (0 <= anchor < {t.size}), got {anchor!r}")
    if not (np.isfinite(spacing) and spacing >= 0):
        raise ValueError(f"spacing must be finite and >= 0, got {spacing!r}")
    return t, a


def _chain(step: np.ndarray, start: int, end: int) -> np.ndarray:
    """``start, step[start], step[step[start]], ...`` until the sentinel ``end``, by pointer doubling.

    ``step`` maps every index to another one strictly closer to the sentinel ``end``
    (which maps to itself). Round ``k`` holds the first ``2**k`` chain members and the
    table ``step`` composed ``2**k`` times; the next round applies that table to every member held,
    which doubles the members, and composes the table with itself. Each round is one
    vectorised gather, and there are ``ceil(log2(chain length))`` rounds.
    """
    members = np.array([start], dtype=np.intp)
    jump = step
    while True:
        ahead = jump[members]
        ahead = ahead[ahead != end]
        if ahead.size == 0:  # the 2**k-th successor of the start is past the end: chain complete
            return members
        done = ahead.size < members.size  # the sentinel was reached within this round
        members = np.concatenate([members, ahead])
        if done:
            return members
        jump = jump[jump]


def select_spaced(time_s: np.ndarray, *, anchor: int, spacing: float) -> np.ndarray:
    r"""The largest set of samples at least ``spacing`` apart that contains the sample ``anchor``.

    Parameters
    ----------
    time_s
        Sample times sorted in non-decreasing order (s, or any unit shared with
        ``spacing``; an integer array, e.g. GPS microseconds, with an integer
        ``spacing`` is compared exactly).
    anchor
        Index of the sample that must be kept (Comby et al. 2003 keep the sample with
        the largest absolute error).
    spacing
        Minimum time between any two samples kept; 0 keeps every sample.

    Returns
    -------
    numpy.ndarray
        Sorted indices into ``time_s`` (``intp``): a set of maximum size among the sets
        that contain ``anchor`` and whose pairwise spacings are all ``>= spacing``.

    Raises
    ------
    ValueError
        ``time_s`` empty, not one-dimensional, not finite or not sorted; ``anchor`` not
        an index; ``spacing`` negative or not finite.

    See Also
    --------
    overbound.methods.confidence_level.confidence_analysis : the procedure that uses it.

    Notes
    -----
    **Algorithm.** Greedy from the anchor: forward, the next sample is the *earliest*
    one at least ``spacing`` after the last sample kept; backward, the *latest* one at
    least ``spacing`` before the first kept. Without a Python loop over samples:

    1. ``nxt[i] = searchsorted(t, t[i] + spacing, side="left")``: the earliest sample
       ``>= t[i] + spacing`` (``n`` when there is none, a sentinel that maps to itself);
       ``prv[i] = searchsorted(t, t[i] - spacing, side="right") - 1``: the latest
       sample ``<= t[i] - spacing`` (``-1`` when none).
    2. The forward chain ``a, nxt[a], nxt[nxt[a]], ...`` by pointer doubling (binary
       lifting): holding the first :math:`2^k` members and the table
       :math:`\mathrm{nxt}^{2^k}`, one gather gives the next :math:`2^k` members and one
       more gives :math:`\mathrm{nxt}^{2^{k+1}} = \mathrm{nxt}^{2^k}\circ\mathrm{nxt}^{2^k}`.
       :math:`\lceil\log_2 L\rceil` rounds for a chain of :math:`L` members, each
       :math:`O(n)`. The backward chain likewise with ``prv``.

    **Optimality (exchange argument).** Let :math:`S` be any admissible set containing
    the anchor :math:`a`, and :math:`s_1 < s_2 < \dots < s_m` its members after
    :math:`a` (by time). Let :math:`g_1, g_2, \dots` be the greedy forward chain
    (:math:`g_0 = a`). By induction :math:`g_k` exists and :math:`t(g_k) \le t(s_k)` for
    :math:`k \le m`: :math:`s_1` is at least ``spacing`` after :math:`a`, and
    :math:`g_1` is the earliest such sample, so :math:`t(g_1) \le t(s_1)`; if
    :math:`t(g_k) \le t(s_k)` then :math:`s_{k+1}` is at least ``spacing`` after
    :math:`s_k`, hence after :math:`g_k`, so it is a candidate for :math:`g_{k+1}`,
    which exists and is no later. (Replacing :math:`s_k` by :math:`g_k` — the exchange —
    keeps :math:`S` admissible.) So the greedy forward part has at least :math:`m`
    members; the mirror argument bounds the part before :math:`a`. The two parts do not
    constrain each other: a sample after :math:`a` and one before are at least
    :math:`2\,` ``spacing`` apart. Hence the greedy set is at least as large as
    :math:`S`. Ties in time are allowed (several stations on one time axis): two
    samples at the same time are never both kept when ``spacing > 0``.

    The maximum-size set is not unique in general; this one is the greedy one
    (earliest-next forward, latest-previous backward), which is deterministic.

    References
    ----------
    .. [1] Comby, D., Farnworth, R., Macabiau, C. (2003), "EGNOS vertical protection
       level assessment", ION GPS/GNSS 2003, section II.2 (second level of the data
       selection: samples at least 360 s apart, always containing the largest |VPE|).

    Examples
    --------
    >>> select_spaced(np.array([0.0, 100, 300, 400, 700, 1000]), anchor=2, spacing=360.0)
    array([2, 4])
    >>> select_spaced(np.array([0.0, 100, 300, 400, 700, 1000]), anchor=0, spacing=360.0)
    array([0, 3, 5])
    """
    t, a = _validate_select_spaced(time_s, anchor, spacing)
    n = t.size
    if spacing == 0:
        return np.arange(n, dtype=np.intp)
    if np.issubdtype(t.dtype, np.integer) and float(spacing).is_integer():
        d = np.asarray(int(spacing), dtype=t.dtype)
    else:
        t = t.astype(np.float64, copy=False)
        d = np.float64(spacing)
    # forward: indices 0..n-1, sentinel n (maps to itself)
    nxt = np.empty(n + 1, dtype=np.intp)
    nxt[:n] = np.searchsorted(t, t + d, side="left")
    nxt[n] = n
    # backward, shifted by one so that the sentinel -1 becomes 0: index i is stored at i + 1
    prv = np.empty(n + 1, dtype=np.intp)
    prv[1:] = np.searchsorted(t, t - d, side="right")  # (latest index <= t - d) + 1
    prv[0] = 0
    after = _chain(nxt, a, n)
    before = _chain(prv, a + 1, 0) - 1
    return np.concatenate([before[:0:-1], after])
