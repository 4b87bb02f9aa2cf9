"""Rendering the report figures to PNG in worker processes, while the pages are being written.

Rendering (matplotlib's Agg draw and the PNG encoder) is most of what a report costs: 52 figures of a
6-day ``overbound analyze`` took 11.9 s of ``savefig`` against about 15 s of analysis on the 2-core
machine. A figure is built in the main process (it needs the analysis), then pickled and drawn by a
pool of worker processes while the main process builds the next one; the page holds a placeholder
until :func:`resolve_figures` swaps in the finished ``<figure>``.

- **The same bytes.** A pickled and unpickled figure draws to the same PNG as the original (the report
  tests compare the pages written both ways); workers are started with ``spawn`` (polars is not
  fork-safe), and nothing in the pages depends on which process drew what.
- **Nothing lost.** A figure a worker fails to draw (a worker killed, a pool broken, a class the worker
  cannot import) is drawn again in the main process from the same pickle; one that does not pickle is
  drawn in the main process at once; an exception of the figure itself is raised as it would be inline.
  Where no pool can be started, every figure is drawn inline. Placeholders name their pool: one resolved
  in another block is an error, never another figure.
- **Off by default in the library.** Without :func:`parallel_figures` active, no pool exists and
  every figure is drawn inline (:func:`overbound.report.page.figure_html`); the CLI
  turns the pool on (``OVERBOUND_FIGURE_PROCESSES``, default: the cores available, at most 4; 0 or 1
  draws inline), started with the command, or at the first figure for a campaign dataset
  (``start=False``: its Dask workers need the memory more than the report needs a warm pool).
"""

from __future__ import annotations

import contextlib
import contextvars
import itertools
import multiprocessing
import os
import pickle
import re
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

from matplotlib.figure import Figure

from overbound.report.style import figure_png

__all__ = [
    "ENV_PROCESSES",
    "FigureRenderer",
    "active_renderer",
    "default_processes",
    "parallel_figures",
    "resolve_figures",
]

#: Environment variable giving the number of figure-rendering processes of the CLI (0 or 1: inline).
ENV_PROCESSES = "OVERBOUND_FIGURE_PROCESSES"
#: More workers than this bring nothing: the main process builds the figures one at a time.
_MAX_PROCESSES = 4
#: Niceness added to the workers: on a machine with few cores their start-up must not slow the analysis.
_NICE = 5
_PLACEHOLDER = re.compile(r"<overbound-figure-(\d+)-(\d+)>")
_RENDERERS = itertools.count(1)
_ACTIVE: contextvars.ContextVar[FigureRenderer | None] = contextvars.ContextVar("renderer", default=None)


class _Unpicklable(Exception):
    """A figure the worker could not unpickle: drawn again in the main process."""


def _draw(payload: bytes, dpi: float) -> bytes:
    """Worker side: unpickle one figure and draw it to PNG bytes."""
    try:
        fig = pickle.loads(payload)
    except Exception as exc:  # a class the worker cannot import: the main process can
        raise _Unpicklable(str(exc)) from None
    return figure_png(fig, dpi=dpi)


def _warm() -> None:
    """Worker start-up: leave Ctrl-C to the main process (which stops the pool), and load matplotlib's Agg
    backend and fonts before the first figure arrives."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    fig = Figure(figsize=(1, 1))
    fig.add_subplot().set_title("0")
    figure_png(fig, dpi=10)


def _ready() -> None:
    """A task that does nothing: submitting one per worker starts them all at once."""


class FigureRenderer:
    """A pool of processes drawing pickled figures; :meth:`submit` returns a placeholder for the page."""

    def __init__(self, processes: int, *, start: bool = True) -> None:
        self._processes = processes
        self._token = next(_RENDERERS)
        self._keys = itertools.count()
        self._pool: ProcessPoolExecutor | None = None
        self._jobs: dict[int, tuple[bytes, float, Future[bytes], Callable[[bytes], str]]] = {}
        if start:
            self.start()

    def start(self) -> None:
        """Start and warm the workers now, while the analysis runs (a no-op once started). Deferred, the
        pool starts at the first figure: a campaign's Dask workers keep its memory until then."""
        if self._pool is not None:
            return
        ctx = multiprocessing.get_context("spawn")
        self._pool = ProcessPoolExecutor(max_workers=self._processes, mp_context=ctx, initializer=_warm)
        try:
            for _ in range(self._processes):  # submitting one task per worker starts them all at once
                self._pool.submit(_ready)
        except BaseException:
            self._pool.shutdown(wait=False, cancel_futures=True)
            raise
        for pid in getattr(self._pool, "_processes", None) or ():
            with contextlib.suppress(OSError, AttributeError):  # their start-up yields to the analysis
                os.setpriority(os.PRIO_PROCESS, pid, min(os.getpriority(os.PRIO_PROCESS, pid) + _NICE, 19))

    @property
    def started(self) -> bool:
        """Whether the worker processes exist (or were asked to start)."""
        return self._pool is not None

    def submit(self, fig: Figure, *, dpi: float, wrap: Callable[[bytes], str]) -> str:
        """Queue ``fig`` for drawing; ``wrap(png)`` later makes its HTML. Returns the placeholder, or the
        finished HTML of a figure that does not pickle (drawn here at once)."""
        try:
            payload = pickle.dumps(fig, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # a lambda formatter, an object of a notebook's __main__...
            return wrap(figure_png(fig, dpi=dpi))
        key = next(self._keys)
        try:
            self.start()
            future = self._pool.submit(_draw, payload, dpi)
        except (BrokenProcessPool, RuntimeError, OSError):  # no pool (gone, or not started): drawn here
            future = Future()
            future.set_exception(BrokenProcessPool("figure pool unavailable"))
        self._jobs[key] = (payload, dpi, future, wrap)
        return f"<overbound-figure-{self._token}-{key}>"

    def html(self, token: int, key: int) -> str:
        """The finished HTML of figure ``key`` (drawn here if its worker could not)."""
        if token != self._token:
            raise RuntimeError("a figure placeholder of another parallel_figures() block")
        payload, dpi, future, wrap = self._jobs[key]
        try:
            png = future.result()
        except (BrokenProcessPool, _Unpicklable):
            png = figure_png(pickle.loads(payload), dpi=dpi)
        return wrap(png)

    def fallbacks(self) -> int:
        """Figures resolved so far that no worker drew (pool broken, or not unpicklable in the worker)."""
        return sum(
            1
            for _, _, f, _ in self._jobs.values()
            if f.done() and isinstance(f.exception(), BrokenProcessPool | _Unpicklable)
        )

    def close(self, *, wait: bool = True) -> None:
        """Stop the workers, cancelling figures not yet resolved; ``wait=False`` returns at once."""
        if self._pool is not None:
            self._pool.shutdown(wait=wait, cancel_futures=True)


def default_processes() -> int:
    """Rendering processes for the CLI: ``$OVERBOUND_FIGURE_PROCESSES``, else the cores this process may
    use, at most 4."""
    value = os.environ.get(ENV_PROCESSES, "").strip()
    if value:
        try:
            return min(max(int(value), 0), 64)
        except ValueError:
            raise ValueError(f"{ENV_PROCESSES}={value!r}: expected a whole number of processes") from None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return min(cores, _MAX_PROCESSES)


@contextmanager
def parallel_figures(processes: int | None = None, *, start: bool = True) -> Iterator[FigureRenderer | None]:
    """Draw the figures of the pages written inside this block in ``processes`` worker processes
    (default :func:`default_processes`); with fewer than 2, draw them inline (yields ``None``).
    ``start=False`` defers starting them to the first figure (:meth:`FigureRenderer.start`)."""
    n = default_processes() if processes is None else processes
    renderer = None
    if n >= 2:
        with contextlib.suppress(OSError, NotImplementedError):  # no process pool here: draw inline
            renderer = FigureRenderer(n, start=start)
    if renderer is None:
        yield None
        return
    token = _ACTIVE.set(renderer)
    failed = True
    try:
        yield renderer
        failed = False
    finally:
        _ACTIVE.reset(token)
        renderer.close(wait=not failed)  # an error does not wait for workers still starting


def active_renderer() -> FigureRenderer | None:
    """The renderer of the enclosing :func:`parallel_figures` block, if any."""
    return _ACTIVE.get()


def resolve_figures(text: str) -> str:
    """``text`` with every figure placeholder replaced by its finished ``<figure>``."""
    if "<overbound-figure-" not in text:
        return text
    renderer = _ACTIVE.get()
    if renderer is None:
        raise RuntimeError("figure placeholders outside parallel_figures(): resolve inside the block")
    return _PLACEHOLDER.sub(lambda m: renderer.html(int(m.group(1)), int(m.group(2))), text)
