"""overbound: GNSS integrity verification from receiver output.

Read a receiver's output into the epoch table (:func:`overbound.io.read`), count the
KPIs of each ICAO service level (:func:`overbound.methods.counting.count_kpis`), and
write the JSON summary and the HTML report (:mod:`overbound.report`).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("overbound")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"

__all__ = ["__version__"]
