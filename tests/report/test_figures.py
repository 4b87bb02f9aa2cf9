"""Figures: Stanford diagram regions and lines, time-series envelope, safety-index histogram, PNG bytes."""

from __future__ import annotations

import struct
import zlib

import matplotlib
import numpy as np
import polars as pl
import pytest
from matplotlib.axes import Axes
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from overbound.analysis import analyze
from overbound.methods.counting import Region
from overbound.report.figures import (
    close_figure,
    envelope,
    figure_png,
    plot_safety_index,
    plot_stanford,
    plot_timeseries,
)

AL = 40.0
SERVICE = "T:40:40"  # same alert limit on both axes: both diagrams hold the same counts
# (PE, PL, epochs) per region; the last UNAVAILABLE rows lie beyond the 60 m plot edge.
ROWS = [
    (Region.NORMAL, 3.0, 15.0, 500),
    (Region.MI, 20.0, 15.0, 3),
    (Region.HMI, 45.0, 30.0, 2),
    (Region.UNAVAILABLE, 5.0, 45.0, 7),
    (Region.UNAVAILABLE, 5.0, 75.0, 2),
    (Region.UNAVAILABLE_MI, 55.0, 50.0, 4),
    (Region.NO_SOLUTION, np.nan, np.nan, 1),
]
# label text expected per region: count and share of the 519 epochs
EXPECTED_LABELS = {
    Region.NORMAL: "Normal operation\n500 (96.34 %)",
    Region.MI: "MI\n3 (0.58 %)",
    Region.HMI: "HMI\n2 (0.39 %)",
    Region.UNAVAILABLE: "System unavailable\n9 (1.73 %)",
    Region.UNAVAILABLE_MI: "Unavailable & MI\n4 (0.77 %)",
}
T0 = np.datetime64("2006-12-27T00:00:00", "us")


def _seconds(s: np.ndarray) -> np.ndarray:
    return T0 + (np.asarray(s) * 1_000_000).astype("timedelta64[us]")


def region_table() -> pl.DataFrame:
    """519 epochs at 1 Hz in shuffled region order; VPE negative to exercise |VPE|."""
    pe = np.concatenate([np.full(n, p) for _, p, _, n in ROWS])
    pl_ = np.concatenate([np.full(n, q) for _, _, q, n in ROWS])
    order = np.random.default_rng(7).permutation(pe.size)
    pe, pl_ = pe[order], pl_[order]
    return pl.DataFrame(
        {
            "time": _seconds(np.arange(pe.size)),
            "station": "SYN",
            "hpe": pe,
            "vpe": -pe,
            "hpl": pl_,
            "vpl": pl_,
        }
    )


@pytest.fixture(scope="module")
def analysis():
    return analyze(region_table(), services=[SERVICE])


def _stanford(analysis, axis: str) -> Axes:
    k = analysis.counting.services["T"].axis(axis)
    return plot_stanford(analysis.counting.histogram(axis, AL), k.stanford, alert_limit=AL, service="T")


def _by_gid(artists, gid: str):
    found = [a for a in artists if a.get_gid() == gid]
    assert len(found) == 1, gid
    return found[0]


@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
def test_stanford_region_labels_carry_counts_and_shares(analysis, axis):
    ax = _stanford(analysis, axis)
    for region, text in EXPECTED_LABELS.items():
        assert _by_gid(ax.texts, f"region-{region.key}").get_text() == text
    note = _by_gid(ax.texts, "stanford-note").get_text()
    assert "519 epochs, AL 40 m: 1 without solution (not drawn)" in note
    assert "2 beyond 60 m (drawn on the border)" in note
    close_figure(ax.figure)


@pytest.mark.parametrize(
    ("axis", "labels"), [("horizontal", ("HPE (m)", "HPL (m)")), ("vertical", ("|VPE| (m)", "VPL (m)"))]
)
def test_stanford_axes_lines_and_title(analysis, axis, labels):
    ax = _stanford(analysis, axis)
    assert (ax.get_xlabel(), ax.get_ylabel()) == labels
    assert ax.get_title() == f"T {axis}"
    assert ax.get_xlim() == (0.0, 60.0) and ax.get_ylim() == (0.0, 60.0)
    assert ax.get_aspect() == 1.0
    al_pe = _by_gid(ax.lines, "alert-limit-pe")
    al_pl = _by_gid(ax.lines, "alert-limit-pl")
    assert list(al_pe.get_xdata()) == [AL, AL]
    assert list(al_pl.get_ydata()) == [AL, AL]
    diagonal = _by_gid(ax.lines, "diagonal")
    assert list(diagonal.get_xdata()) == list(diagonal.get_ydata()) == [0.0, 60.0]
    close_figure(ax.figure)


def test_stanford_histogram_on_log_colour_scale(analysis):
    ax = _stanford(analysis, "horizontal")
    (image,) = ax.images
    assert isinstance(image.norm, LogNorm)
    assert image.norm.vmin == 1.0 and image.norm.vmax == 500.0
    data = image.get_array()
    # every drawn epoch is in the image, empty bins are masked (not coloured)
    assert data.sum() == 518
    assert np.ma.count(data) == 6  # six occupied (PE, PL) bins
    # image rows are PL, columns PE: the 500 normal epochs sit at PE 3 m, PL 15 m (0.3 m bins)
    assert data[50, 10] == 500
    assert image.get_extent() == [0.0, 60.0, 0.0, 60.0]
    assert ax.figure.axes[1].get_ylabel() == "epochs per bin"
    close_figure(ax.figure)


@pytest.mark.parametrize(
    ("pe", "pl_", "place"),
    [
        (3.0, 15.0, (0.36 * AL, 50.0)),  # nothing under the classic place: keep it
        (14.0, 50.0, (0.66 * AL, 55.0)),  # epochs under it: move up and right, still unavailable
    ],
)
def test_stanford_labels_avoid_the_data(pe, pl_, place):
    table = region_table().with_columns(hpe=pl.lit(pe), hpl=pl.lit(pl_))
    k = analyze(table, services=[SERVICE]).counting
    ax = plot_stanford(k.histogram("horizontal", AL), k.services["T"].horizontal.stanford, alert_limit=AL)
    label = _by_gid(ax.texts, "region-unavailable")
    assert label.get_position() == pytest.approx(place)
    close_figure(ax.figure)


def test_stanford_draws_on_given_axes_without_touching_rcparams(analysis):
    before = dict(matplotlib.rcParams)
    fig = Figure()
    ax = fig.add_subplot()
    assert _stanford_on(ax, analysis) is ax
    assert len(fig.axes) == 2  # the diagram and its colour bar
    assert dict(matplotlib.rcParams) == before


def _stanford_on(ax: Axes, analysis) -> Axes:
    k = analysis.counting.services["T"].horizontal
    return plot_stanford(analysis.counting.histogram("horizontal", AL), k.stanford, alert_limit=AL, ax=ax)


# ---------------------------------------------------------------------------
# envelope and time series


def test_envelope_keeps_each_bins_min_and_max():
    rng = np.random.default_rng(3)
    t = np.arange(10_000, dtype=np.int64) * 1_000_000
    v = rng.normal(size=t.size)
    v[::37] = np.nan
    x, y = envelope(t, v, bins=100)
    assert x.size == y.size == 200 and not np.isnan(y).any()
    width = t[-1] / 100
    b = (t / width).astype(int)
    assert np.array_equal(y[0::2], [np.nanmin(v[b == k]) for k in range(100)])
    assert np.array_equal(y[1::2], [np.nanmax(v[b == k]) for k in range(100)])
    assert y.max() == np.nanmax(v) and y.min() == np.nanmin(v)


@pytest.mark.parametrize(("missing", "breaks"), [(1, 0), (2, 1), (500, 1)])
def test_envelope_breaks_at_gaps_of_two_intervals(missing, breaks):
    s = np.concatenate([np.arange(100), np.arange(100 + missing, 300 + missing)])
    _, y = envelope(s * 1_000_000, np.ones(s.size), bins=100_000)
    assert np.count_nonzero(np.isnan(y)) == breaks
    assert np.count_nonzero(~np.isnan(y)) == 2 * s.size == 600


def test_envelope_of_pooled_stations_ignores_row_order():
    rng = np.random.default_rng(5)
    t = np.tile(np.arange(5_000, dtype=np.int64) * 1_000_000, 2)  # two stations, sorted by station
    v = rng.exponential(size=t.size)
    x1, y1 = envelope(t, v, bins=50)
    order = np.argsort(t, kind="stable")
    x2, y2 = envelope(t[order], v[order], bins=50)
    assert np.array_equal(x1, x2) and np.array_equal(y1, y2)


def test_envelope_of_a_million_epochs_is_small():
    t = np.arange(1_000_000, dtype=np.int64) * 1_000_000
    x, _ = envelope(t, np.sin(np.arange(t.size) / 1e4))
    assert x.size <= 2 * 2000
    assert x.dtype == np.dtype("datetime64[us]")


@pytest.mark.parametrize(("axis", "pe_max"), [("horizontal", 55.0), ("vertical", 55.0)])
def test_timeseries_lines(axis, pe_max):
    ax = plot_timeseries(region_table(), axis=axis, alert_limit=AL)
    pe_line = _by_gid(ax.lines, "pe")
    pl_line = _by_gid(ax.lines, "pl")
    assert np.nanmax(pe_line.get_ydata()) == pe_max  # |VPE|: the table's VPE is negative
    assert np.nanmax(pl_line.get_ydata()) == 75.0
    assert list(_by_gid(ax.lines, "alert-limit").get_ydata()) == [AL, AL]
    assert ax.get_xlabel() == "GPS time"
    assert ax.get_ylim()[0] == 0.0
    close_figure(ax.figure)


def test_timeseries_without_alert_limit_or_epochs():
    ax = plot_timeseries(region_table().clear(), axis="vertical")
    assert [a.get_gid() for a in ax.lines] == []
    assert [t.get_text() for t in ax.texts] == ["no epochs"]
    with pytest.raises(ValueError, match="axis must be"):
        plot_timeseries(region_table(), axis="up")


def test_safety_index_histogram():
    ax = plot_safety_index(region_table(), axis="horizontal")
    stairs = _by_gid(ax.patches, "si-histogram")
    counts, edges = stairs.get_data().values, stairs.get_data().edges
    assert counts.sum() == 518  # epochs with a solution and PL > 0
    assert edges[-1] == pytest.approx(1.05 * 1.5)  # max SI is 45/30
    line = _by_gid(ax.lines, "si-one")
    assert list(line.get_xdata()) == [1.0, 1.0]
    # above SI = 1: MI (20/15), HMI (45/30) and unavailable & MI (55/50)
    assert line.get_label() == "SI = 1: 9 of 518 epochs above"
    assert ax.get_yscale() == "log"
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# PNG output


def _png_chunks(png: bytes) -> list[bytes]:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = [], 8
    while i < len(png):
        (n,) = struct.unpack(">I", png[i : i + 4])
        kind = png[i + 4 : i + 8]
        assert zlib.crc32(png[i + 4 : i + 8 + n]) == struct.unpack(">I", png[i + 8 + n : i + 12 + n])[0]
        out.append(kind)
        i += 12 + n
    return out


def test_figure_png_is_reproducible_and_carries_no_metadata(analysis):
    pngs = []
    for _ in range(2):
        ax = _stanford(analysis, "vertical")
        pngs.append(figure_png(ax.figure, dpi=80))
        close_figure(ax.figure)
    assert pngs[0] == pngs[1]
    chunks = _png_chunks(pngs[0])
    assert b"tEXt" not in chunks and b"iTXt" not in chunks
    assert chunks[0] == b"IHDR" and chunks[-1] == b"IEND"
    width, height = struct.unpack(">II", pngs[0][16:24])
    assert (width, height) == (400, 368)  # 5.0 x 4.6 in at 80 dpi


def test_close_figure_releases_the_figure(analysis):
    ax = _stanford(analysis, "horizontal")
    fig = ax.figure
    close_figure(fig)
    assert fig.axes == []
