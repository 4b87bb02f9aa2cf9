"""Figures drawn by worker processes: the same pages, byte for byte, and nothing lost when a worker dies."""

from __future__ import annotations

import os
import signal

import numpy as np
import polars as pl
import pytest
from matplotlib.ticker import FuncFormatter

from overbound.analysis import analyze
from overbound.methods.confidence_level import confidence_analysis
from overbound.report.confidence import write_confidence_report
from overbound.report.html import render_report
from overbound.report.page import figure_html
from overbound.report.rendering import (
    ENV_PROCESSES,
    active_renderer,
    default_processes,
    parallel_figures,
    resolve_figures,
)
from overbound.report.style import new_figure
from overbound.simulate import SimulationConfig, simulate


def _table() -> pl.DataFrame:
    n = 7200
    rng = np.random.default_rng(5)
    time = np.datetime64("2024-01-07T00:00:00", "us") + (np.arange(n) * 1_000_000).astype("timedelta64[us]")
    vpl = 14.0 + 3.0 * np.sin(np.arange(n) / 900.0)
    hpl = 0.6 * vpl
    return pl.DataFrame(
        {
            "time": time,
            "station": "SYN",
            "hpe": np.abs(rng.normal(0.0, 0.1, n)) * hpl,
            "vpe": rng.normal(0.0, 0.1, n) * vpl,
            "hpl": hpl,
            "vpl": vpl,
        }
    )


def _axes(label: str):
    ax = new_figure(4.0, 3.0).add_subplot()
    ax.plot([0, 1, 2], [1, 3, 2], label=label)
    ax.set_yscale("log")  # the epoch-count formatter and log ticks pickle too
    ax.set_title(label)
    return ax


def test_report_drawn_by_workers_is_byte_identical():
    analysis = analyze(_table(), services=["NPA", "LPV-200"], evt=(), parametric=True)
    inline = render_report(analysis)
    with parallel_figures(2) as renderer:
        assert renderer is not None and active_renderer() is renderer
        pooled = render_report(analysis)
        assert renderer.fallbacks() == 0  # every figure was drawn by a worker
    assert active_renderer() is None
    assert "<overbound-figure-" not in pooled
    assert pooled.count("<img ") == inline.count("<img ") > 10
    assert pooled == inline


def test_standalone_page_drawn_by_workers_is_byte_identical(tmp_path):
    sim = simulate(SimulationConfig(days=0.5, seed=3, tail_fraction=0.0, anomalies=("band:15:16:3",)))
    cl = confidence_analysis(sim.table, axis="vertical", min_samples=20)
    a = write_confidence_report([cl], tmp_path / "inline").read_bytes()
    with parallel_figures(2):
        b = write_confidence_report([cl], tmp_path / "pooled").read_bytes()
    assert b"data:image/png" in a and a == b


def test_placeholders_resolve_only_inside_the_block():
    with parallel_figures(2):
        html = figure_html(_axes("x"), name="x", alt="x", caption="x")
        assert html.startswith("<overbound-figure-")
        assert resolve_figures(html).startswith('<figure><img src="data:image/png;base64,')
    with pytest.raises(RuntimeError, match="parallel_figures"):  # a page finished after its pool is gone
        resolve_figures(html)
    with parallel_figures(2), pytest.raises(RuntimeError, match="another"):  # or in another pool's block
        resolve_figures(html)


def test_figure_that_does_not_pickle_is_drawn_inline():
    def unpicklable():
        ax = _axes("c")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _p: f"{v:.1f}"))  # a lambda: no pickle
        return ax

    inline = figure_html(unpicklable(), name="c", alt="c", caption="c")
    with parallel_figures(2):
        assert figure_html(unpicklable(), name="c", alt="c", caption="c") == inline


def test_pool_gone_or_worker_killed_draws_in_this_process():
    inline = figure_html(_axes("a"), name="a", alt="a", caption="a")
    with parallel_figures(2) as renderer:
        first = figure_html(_axes("a"), name="a", alt="a", caption="a")
        for pid in list(renderer._pool._processes):  # a worker killed (OOM killer, Ctrl-C in a child)
            os.kill(pid, signal.SIGKILL)
        second = figure_html(_axes("a"), name="a", alt="a", caption="a")
        renderer._pool.shutdown(wait=True)  # and a pool already shut down
        third = figure_html(_axes("a"), name="a", alt="a", caption="a")
        assert [resolve_figures(x) for x in (first, second, third)] == [inline] * 3


def test_processes_from_the_environment(monkeypatch):
    monkeypatch.setenv(ENV_PROCESSES, "1")
    assert default_processes() == 1
    with parallel_figures() as renderer:
        assert renderer is None  # one process: drawn inline, no placeholder
        assert figure_html(_axes("b"), name="b", alt="b", caption="b").startswith("<figure")
    monkeypatch.setenv(ENV_PROCESSES, "two")
    with pytest.raises(ValueError, match=ENV_PROCESSES):
        default_processes()
    monkeypatch.delenv(ENV_PROCESSES)
    assert 1 <= default_processes() <= 4


def test_deferred_pool_starts_at_the_first_figure():
    inline = figure_html(_axes("d"), name="d", alt="d", caption="d")
    with parallel_figures(2, start=False) as renderer:
        assert renderer is not None and not renderer.started  # no process held while a campaign runs
        html = figure_html(_axes("d"), name="d", alt="d", caption="d")
        assert renderer.started and html.startswith("<overbound-figure-")
        assert resolve_figures(html) == inline
        assert renderer.fallbacks() == 0  # drawn by a worker of the pool started then
    with parallel_figures(2, start=False) as renderer:
        assert not renderer.started  # a block without figures never starts one
