"""The epoch table: overbound's one data model.

One row per receiver epoch. Every reader returns this table, every method takes it.
This module is the single document that defines it; the table of docs/epoch-table.md is generated
from :data:`COLUMNS` (``overbound schema``; a test keeps the two equal).

Time base
---------
``time`` is **GPS time** (GPST: continuous, no leap seconds, aligned with UTC on
1980-01-06), held as a naive ``Datetime("us")``. It is *not* UTC: readers convert
UTC-tagged inputs by adding the GPS-UTC leap seconds. ISO 8601 strings written by
overbound are GPS time too and carry no ``Z``.

Sign conventions
----------------
Errors are *estimate minus truth* in the local east-north-up frame of the true
antenna position: ``vpe`` > 0 means the solution is above the truth.
``hpe`` = sqrt(east**2 + north**2) >= 0.

Epochs without a position solution stay in the table with NaN errors and NaN
protection levels; they count as unavailable for every service.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np
import polars as pl

__all__ = [
    "COLUMNS",
    "OPTIONAL",
    "REQUIRED",
    "Column",
    "InputError",
    "ReadReport",
    "as_numpy",
    "empty_epochs",
    "schema_markdown",
    "validate_epochs",
]


@dataclass(frozen=True, slots=True)
class Column:
    """One column of the epoch table."""

    name: str
    dtype: pl.DataType
    unit: str
    meaning: str
    required: bool


COLUMNS: tuple[Column, ...] = (
    Column("time", pl.Datetime("us"), "GPST", "epoch time, GPS time scale (no leap seconds)", True),
    Column("station", pl.Categorical(), "-", "receiver / station identifier", True),
    Column("hpe", pl.Float64(), "m", "horizontal position error, sqrt(east^2+north^2), >= 0", True),
    Column("vpe", pl.Float64(), "m", "vertical position error, estimate minus truth, up positive", True),
    Column("hpl", pl.Float64(), "m", "horizontal protection level", True),
    Column("vpl", pl.Float64(), "m", "vertical protection level", True),
    Column("east", pl.Float64(), "m", "east error, estimate minus truth", False),
    Column("north", pl.Float64(), "m", "north error, estimate minus truth", False),
    Column("nsv", pl.Int16(), "-", "number of satellites used in the solution", False),
    Column(
        "mode", pl.Categorical(), "-", "solution mode as the source names it (e.g. PA, NPA, SBAS, 3D)", False
    ),
    Column(
        "alert",
        pl.Boolean(),
        "-",
        "receiver raised an integrity alert / flagged the solution unusable",
        False,
    ),
    Column(
        "hal",
        pl.Float64(),
        "m",
        "horizontal alert limit in force, as the receiver logs it (NaN: none)",
        False,
    ),
    Column(
        "val", pl.Float64(), "m", "vertical alert limit in force, as the receiver logs it (NaN: none)", False
    ),
)
REQUIRED: tuple[str, ...] = tuple(c.name for c in COLUMNS if c.required)
OPTIONAL: tuple[str, ...] = tuple(c.name for c in COLUMNS if not c.required)
_BY_NAME = MappingProxyType({c.name: c for c in COLUMNS})


class InputError(ValueError):
    """Bad input that cannot be recovered: unknown format, missing column, malformed line.

    The message is one line naming the file, the line when there is one, and what was
    expected, as in ``data.pos:17: expected 15 fields, got 11``.
    """

    def __init__(self, source: str, message: str, line: int | None = None) -> None:
        self.source = source
        self.line = line
        self.reason = message  # without the file and line
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True, slots=True)
class ReadReport:
    """What a reader did with its input.

    Attributes
    ----------
    source : the file (or stream) name.
    format : the format that was read (``rtklib-pos``, ``glab``, ...).
    rows_read : data rows (lines, messages) seen.
    rows_kept : epochs in the returned table (including no-solution epochs).
    rejected : rows removed from the table, by reason (malformed line, duplicate time...).
    invalidated : rows kept as *no-solution* epochs (NaN errors and PLs) because a value
        was unusable (NaN or negative PL, NaN error), by reason. They count as unavailable.
    first_bad : ``"<line>: <reason>"`` of the first rejected or invalidated row, or ``""``.
    notes : free-form remarks (e.g. the reference position used).
    truth : False when the input has no truth (a flight log without a reference trajectory): its
        errors are unknown (NaN) beside valid protection levels, and only what the PLs give is analysed.
    invalid_rows, invalid_reasons : while the table is being read, the rows (of the returned table)
        that were invalidated and why, so that removing rows afterwards (a time window, a truth's
        span: :meth:`keep`) recounts ``invalidated`` over the rows kept; not compared, not written.
    """

    source: str
    format: str
    rows_read: int
    rows_kept: int
    rejected: dict[str, int] = field(default_factory=dict)
    invalidated: dict[str, int] = field(default_factory=dict)
    first_bad: str = ""
    notes: tuple[str, ...] = ()
    truth: bool = True
    invalid_rows: np.ndarray | None = field(default=None, compare=False, repr=False)
    invalid_reasons: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def n_rejected(self) -> int:
        return sum(self.rejected.values())

    @property
    def unaccounted(self) -> int:
        """Rows neither kept nor counted as rejected: ``rows_read - rows_kept - n_rejected``.

        Every reader keeps this at 0 (invalidated rows are kept, as no-solution rows), so
        that nothing read is lost without a count.
        """
        return self.rows_read - self.rows_kept - self.n_rejected

    def keep(self, kept: np.ndarray, reason: str) -> ReadReport:
        """The report once the rows where ``kept`` (one per row of the table) is False are removed, counted
        as rejected for ``reason``; ``invalidated`` recounted over the rows kept (an invalidated row
        removed counts once, as rejected), and the invalidated rows renumbered in the smaller table."""
        kept = np.asarray(kept, dtype=bool)
        dropped = int(kept.size - np.count_nonzero(kept))
        if not dropped:
            return self
        rejected = {**self.rejected, reason: self.rejected.get(reason, 0) + dropped}
        rows, reasons, invalidated = self.invalid_rows, self.invalid_reasons, self.invalidated
        if rows is not None and reasons is not None:
            stay = kept[rows]
            rows, reasons = (np.cumsum(kept) - 1)[rows[stay]], reasons[stay]
            names, counts = np.unique(reasons, return_counts=True)
            invalidated = dict(zip(names.tolist(), counts.tolist(), strict=True))
        return replace(self, rows_kept=int(np.count_nonzero(kept)), rejected=rejected,
                       invalidated=invalidated, invalid_rows=rows, invalid_reasons=reasons)  # fmt: skip

    def to_dict(self) -> dict:
        return {
            "source": self.source,
            "format": self.format,
            "rows_read": self.rows_read,
            "rows_kept": self.rows_kept,
            "rejected": dict(sorted(self.rejected.items())),
            "n_rejected": self.n_rejected,
            "invalidated": dict(sorted(self.invalidated.items())),
            "n_invalidated": sum(self.invalidated.values()),
            "first_bad": self.first_bad,
            "notes": list(self.notes),
            **({} if self.truth else {"truth": False}),
        }


def empty_epochs() -> pl.DataFrame:
    """An epoch table with no rows and the required columns."""
    return pl.DataFrame(schema={name: _BY_NAME[name].dtype for name in REQUIRED})


def validate_epochs(df: pl.DataFrame, source: str = "<table>") -> pl.DataFrame:
    """Check and normalise an epoch table; return it with canonical dtypes and column order.

    Raises
    ------
    InputError
        A required column is missing, ``hpe`` or a protection level is negative, or
        times within a station are duplicated or go backwards. The message names the
        first offending row (1-based row of the table).

    Notes
    -----
    NaN errors and protection levels are allowed: they mark epochs without a
    solution. A row with a protection level but NaN error (or the reverse) is
    also treated as no-solution by the KPIs. Readers reject negative PLs row by
    row with a count; here they are an error because the table is meant to be clean.
    """
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise InputError(
            source, f"missing required column(s) {', '.join(missing)}; have {', '.join(df.columns)}"
        )
    extra = [c for c in df.columns if c not in _BY_NAME]
    cols = [c.name for c in COLUMNS if c.name in df.columns] + extra
    df = df.select(cols).with_columns(
        [pl.col(c).cast(_BY_NAME[c].dtype, strict=True) for c in cols if c in _BY_NAME]
    )
    for name in ("hpe", "hpl", "vpl"):
        bad = df.select((pl.col(name) < 0).arg_true().first()).item()
        if bad is not None:
            raise InputError(source, f"negative {name} = {df[name][bad]} (must be >= 0)", line=bad + 1)
    _check_monotonic(df, source)
    return df


def _check_monotonic(df: pl.DataFrame, source: str) -> None:
    """Times must strictly increase within each station, in table order."""
    if df.height < 2:
        return
    step = df.select(
        (
            (pl.col("time").diff() <= pl.duration(microseconds=0))
            & (pl.col("station") == pl.col("station").shift(1))
        )
        .fill_null(False)
        .alias("bad")
    )["bad"]
    idx = step.arg_true()
    if len(idx):
        i = int(idx[0])
        what = "duplicate" if df["time"][i] == df["time"][i - 1] else "backward"
        raise InputError(
            source,
            f"{what} time {df['time'][i]} after {df['time'][i - 1]} (station {df['station'][i]})",
            line=i + 1,
        )


def schema_markdown() -> str:
    """The documentation table (docs/epoch-table.md) of the epoch table's columns."""
    rows = ["| column | dtype | unit | required | meaning |", "|---|---|---|---|---|"]
    for c in COLUMNS:
        dtype = "Datetime[us]" if isinstance(c.dtype, pl.Datetime) else str(c.dtype)
        rows.append(f"| `{c.name}` | {dtype} | {c.unit} | {'yes' if c.required else 'no'} | {c.meaning} |")
    return "\n".join(rows)


def as_numpy(series: pl.Series) -> np.ndarray:
    """A numeric or boolean column as one numpy array; Datetime as int64 microseconds.

    Zero-copy for a single chunk. A Parquet read gives one chunk per row group, and
    polars' own ``to_numpy`` of a chunked column is an order of magnitude slower than
    concatenating the chunks' zero-copy views, which is what this does.
    """
    if isinstance(series.dtype, pl.Datetime):
        series = series.dt.epoch("us")
    if series.n_chunks() == 1:
        return series.to_numpy()
    return np.concatenate([chunk.to_numpy() for chunk in series.get_chunks()])
