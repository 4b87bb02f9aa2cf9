"""Helpers shared by the benchmark scripts (imported as ``_timing`` from this folder).

:func:`median_time` times a Python call; :func:`run_r` runs an R script with evd loaded on arrays
handed over as binary files, for the ratios against R's evd (optional: without ``Rscript`` or evd it
says so and returns ``None``).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np


def median_time(fn: Callable[[], object], repeat: int) -> float:
    """Median wall time (s) of ``repeat`` calls after one warm-up call."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run_r(script: str, arrays: Mapping[str, np.ndarray]) -> dict[str, float] | None:
    """Run ``script`` in ``Rscript`` with evd loaded and ``arrays`` defined; parse its ``key value`` lines.

    Parameters
    ----------
    script
        R code; it sees one numeric vector per entry of ``arrays`` (NaN arrives as ``NA``) and
        reports by printing lines ``key value`` (``cat("key", value, "\\n")``). Time inside R with
        ``system.time`` so that R's start-up and the data loading are not counted.
    arrays
        Name -> array, written as little-endian float64 files in a temporary folder (deleted after).

    Returns
    -------
    dict or None
        ``key -> value`` of the printed lines; ``None`` (with a line saying why) when ``Rscript``
        or evd is not installed or the script fails.
    """
    if shutil.which("Rscript") is None:
        print("R not available (no Rscript): no R evd ratio")
        return None
    with tempfile.TemporaryDirectory() as d:
        lines = [
            'if (!requireNamespace("evd", quietly = TRUE)) quit(status = 3)',
            "suppressMessages(library(evd))",
        ]
        for name, a in arrays.items():
            v = np.ascontiguousarray(a, dtype="<f8").ravel()
            path = Path(d) / f"{name}.bin"
            v.tofile(path)
            lines.append(f'{name} <- readBin("{path}", "double", n = {v.size}, size = 8, endian = "little")')
            lines.append(f"{name}[is.nan({name})] <- NA")
        path = Path(d) / "script.R"
        path.write_text("\n".join([*lines, script]), encoding="utf-8")
        r = subprocess.run(["Rscript", str(path)], capture_output=True, text=True, check=False)
    if r.returncode == 3:
        print("R not available (Rscript without the evd package): no R evd ratio")
        return None
    if r.returncode != 0:
        print("R evd failed:", r.stderr.strip()[-300:])
        return None
    out = {}
    for line in r.stdout.splitlines():
        parts = line.split()
        if len(parts) == 2:
            out[parts[0]] = float(parts[1])
    return out
