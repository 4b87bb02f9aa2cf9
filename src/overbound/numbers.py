"""Probabilities as text a reader can accept.

No probability below :data:`PRINT_FLOOR` (1e-15) is printed as a number: such a value says more
about the tail of a model than about the system, and a reader cannot check it against any
campaign. It reads ``< 1e-15``; the exact value stays in the JSON (``log10_*`` keys).
"""

from __future__ import annotations

import math

__all__ = [
    "PRINT_FLOOR",
    "TINY",
    "format_percent",
    "format_probability",
    "format_share",
    "log10_or_none",
    "mantissa_exponent",
]

#: Below this a probability is printed as ``< 1e-15``.
PRINT_FLOOR = 1e-15
#: Below this a float64 value is taken from its log10 (subnormals lose digits).
TINY = 1e-300


def mantissa_exponent(p: float | None, log10_p: float | None = None) -> tuple[float, int] | None:
    r"""``(m, e)`` with :math:`p = m \cdot 10^e`, :math:`1 \le m < 10`; from ``log10_p`` when ``p`` is tiny.

    ``p`` below :data:`TINY` (or 0, or ``None``) is taken from ``log10_p`` when that is finite, so a
    probability that underflows a float64 keeps its order of magnitude. ``None`` when neither gives
    a positive finite value (a true 0 has ``log10_p = -inf``). The mantissa is rounded to three
    significant digits (9.996 becomes 1.00 of the next decade).

    >>> mantissa_exponent(0.0, -411.9)
    (1.26, -412)
    >>> mantissa_exponent(2.5e-7)
    (2.5, -7)
    """
    if p is not None and math.isfinite(p) and p >= TINY:
        lg = math.log10(p)
    elif log10_p is not None and math.isfinite(log10_p):
        lg = float(log10_p)
    else:
        return None
    e = math.floor(lg)
    m = round(10.0 ** (lg - e), 2)
    if m >= 10.0:
        m, e = round(m / 10.0, 2), e + 1
    return m, e


def log10_or_none(p: float | None, log10_p: float | None = None) -> float | None:
    """``log10(p)``, from ``log10_p`` when ``p`` underflows; ``None`` for 0, ``None`` or NaN."""
    if p is not None and math.isfinite(p) and p >= TINY:
        return math.log10(p)
    if log10_p is not None and math.isfinite(log10_p):
        return float(log10_p)
    return None


def format_probability(p: float | None, log10_p: float | None = None) -> str:
    """A probability as plain text: ``0.0123`` down to 0.001, else ``1.23e-08``; ``< 1e-15`` below that.

    ``0`` only for a true zero (``p == 0`` with no finite ``log10_p``), ``n.a.`` for ``None``/NaN.

    >>> format_probability(0.0, -411.9), format_probability(0.0123), format_probability(3e-8)
    ('< 1e-15', '0.0123', '3e-08')
    """
    if p is not None and math.isfinite(p) and 1e-3 <= p:
        return f"{p:.3g}"
    me = mantissa_exponent(p, log10_p)
    if me is None:
        return "0" if p == 0 else "n.a."
    m, e = me
    if e < -15:  # m >= 1, so this is p < PRINT_FLOOR
        return "< 1e-15"
    return f"{m:g}e{e:+03d}"


def format_percent(x: float | None, digits: int = 3) -> str:
    """A share as a percentage with ``digits`` decimals; ``n.a.`` for ``None``/NaN."""
    if x is None or not math.isfinite(x):
        return "n.a."
    return f"{100.0 * x:.{digits}f} %"


def format_share(n: int, total: int) -> str:
    """``n/total`` in percent with just enough decimals not to round a nonzero share to 0 or 100."""
    if total <= 0:
        return "n.a."
    if n == 0 or n == total:
        return f"{100 * n // total} %"
    p = 100.0 * n / total
    for decimals in range(2, 10):
        text = f"{p:.{decimals}f}"
        if float(text) not in (0.0, 100.0):
            return f"{text} %"
    return f"{p:.2e} %"
