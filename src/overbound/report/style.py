"""The figure style and the PNG writer: everything a process needs to draw a finished figure.

Kept apart from the plotting modules so that a rendering worker (:mod:`overbound.report.rendering`)
unpickles and draws a figure importing matplotlib alone (about 1 s), not the analysis stack; the tick
formatters the figures carry are here for the same reason (a pickled figure names them by module).
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator
from contextlib import contextmanager

import matplotlib
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator

__all__ = [
    "STYLE",
    "close_figure",
    "confidence_label",
    "count_label",
    "figure_png",
    "log_scale",
    "new_figure",
    "power_label",
    "style",
]

#: rc settings of every overbound figure (applied through :func:`style`, never globally).
#: DejaVu Sans ships with matplotlib, so the same figure renders to the same bytes anywhere.
STYLE: dict[str, object] = {
    "font.family": "DejaVu Sans",
    "font.size": 8.5,
    "axes.titlesize": 10,
    "axes.titleweight": "bold",
    "axes.labelsize": 9,
    "axes.linewidth": 0.8,
    "axes.edgecolor": "#333333",
    "axes.grid": True,
    "axes.axisbelow": True,
    "grid.color": "#d9d9d9",
    "grid.linewidth": 0.5,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 7.5,
    "legend.framealpha": 0.9,
    "lines.linewidth": 0.8,
    "path.simplify": True,
    "agg.path.chunksize": 20_000,
    "savefig.facecolor": "white",
    "svg.hashsalt": "overbound",
    "svg.fonttype": "path",
}


@contextmanager
def style() -> Iterator[None]:
    """The overbound figure style, as a context (wraps :func:`matplotlib.rc_context`)."""
    with matplotlib.rc_context(STYLE):
        yield


def new_figure(width: float, height: float) -> Figure:
    """A :class:`~matplotlib.figure.Figure` outside pyplot (no global state, no display)."""
    with style():
        return Figure(figsize=(width, height), dpi=100)


def close_figure(fig: Figure) -> None:
    """Release a figure: ``plt.close`` when pyplot manages it, else clear it."""
    if getattr(fig.canvas, "manager", None) is not None:
        import matplotlib.pyplot as plt

        plt.close(fig)
    else:
        fig.clear()


def figure_png(fig: Figure, *, dpi: float = 120) -> bytes:
    """The figure as PNG bytes, with no ``Software`` or date metadata, so reruns give the same bytes."""
    buf = io.BytesIO()
    with style():
        fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def count_label(value: float, _pos: int | None = None) -> str:
    """Tick label of an epoch count on a log axis: a plain integer (1, 10, 1,000), below 1 as ``%g``."""
    return f"{value:,.0f}" if value >= 1 else f"{value:g}"


def confidence_label(value: float, _pos: object = None) -> str:
    """Tick label of a confidence level on a logit axis: ``10⁻ᵏ`` near 0, ``1−10⁻ᵏ`` near 1."""
    if value >= 0.5:
        q = 1.0 - value
        if q > 0:  # 1 - value carries the rounding of value: snap to the power of ten it stands for
            k = round(math.log10(q))
            q = 10.0**k if abs(q / 10.0**k - 1.0) < 1e-6 else q
        return "1" if q <= 0 else (f"{value:g}" if q >= 1e-3 else f"1−{power_label(q)}")
    return f"{value:g}" if value >= 1e-3 else power_label(value)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def power_label(value: float, _pos: object = None) -> str:
    """Tick label of a log axis in plain text: ``1``, ``10``, ``10⁻³``, ``2·10⁵`` (Unicode superscripts).

    matplotlib's default labels are mathtext (``$10^{-3}$``), whose parser costs about 25 ms per new
    label in every process that draws; DejaVu Sans has the superscript glyphs, so the text is the same.
    The mantissa is rounded to three digits before the power is chosen (9.9999999e-4 is ``10⁻³``).
    """
    if not math.isfinite(value) or value <= 0:
        return ""
    mant_text, exp_text = f"{value:.2e}".split("e")
    mant, exp = float(mant_text), int(exp_text)
    if exp in (0, 1):
        return f"{mant * 10**exp:g}"
    power = "10" + str(exp).translate(_SUPERSCRIPT)
    return power if mant == 1.0 else f"{mant:g}·{power}"


def log_scale(ax: Axes, which: str = "y") -> None:
    """Put ``ax``'s ``which`` axis (``x`` or ``y``) on a log scale labelled by :func:`power_label`, with
    minor ticks at 2 and 5 times each power (matplotlib's eight per decade are most of a figure's drawing
    cost on an axis of many decades, and add little to reading it)."""
    axis = ax.yaxis if which == "y" else ax.xaxis
    (ax.set_yscale if which == "y" else ax.set_xscale)("log")
    axis.set_major_formatter(FuncFormatter(power_label))
    axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
