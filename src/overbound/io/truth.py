"""A truth trajectory for a moving receiver (``--truth FILE``): its positions interpolated to the receiver's
epochs, and the errors taken against them (issue 16).

Accepted files (content decides, as :func:`overbound.io.open.sniff` does; gzip handled):

* an **RTKLIB** ``.pos`` solution file (e.g. a post-processed RTK/PPK solution of the same run), any
  variant :func:`overbound.io.rtklib.read_pos_positions` parses: calendar or week/tow time in GPST, UTC
  or JST (UTC/JST converted to GPS time), latitude/longitude/height (degrees or d-m-s, ellipsoidal) or
  x/y/z-ecef; protection-level columns are not needed. Every quality flag ``Q`` is kept except ``Q=0``
  (no solution), unless ``quality`` names the ones to keep (``(1,)``: fixed solutions only);
* a **CSV** table: a header line, then one sample per line, comma separated, ``#`` lines and blank
  lines skipped. Column names (case-insensitive): a time, ``time`` (ISO 8601 GPS time without a zone
  designator, ``2006-12-27T00:04:30.5`` or with a blank) or ``gps_seconds`` (seconds since
  1980-01-06T00:00:00 GPS time) or ``week`` and ``tow``; and a position, ``lat``, ``lon``, ``height``
  (degrees, degrees, ellipsoidal metres, WGS-84) or ``x``, ``y``, ``z`` (ECEF metres). Other columns
  are ignored.

A sample whose fields do not parse is counted (``malformed line``) with its line, a repeated time is
counted (``duplicate_time``, the first kept), and a time going backwards is an :class:`InputError`
naming its line, as the readers of receiver files do.

Interpolation (:meth:`Truth.at`) is per ECEF coordinate between the truth samples that bracket an epoch.
The default is a cubic spline (``scipy.interpolate.CubicSpline``, not-a-knot ends) over each stretch of
samples without a gap, ``linear`` on request. Why cubic: the error of linear interpolation over a step
``h`` is at most ``h**2 / 8 * max|a|`` (the remainder of the degree-1 interpolant, Burden & Faires,
*Numerical Analysis*, 9th ed., Thm. 3.3), ``a`` the acceleration: in a 30-degree banked turn at 70 m/s
(``a = g tan 30° = 5.7 m/s²``) a 1 Hz truth is off by up to 0.7 m, a 10 Hz truth by 7 mm. The cubic
spline's error is ``5/384 * h**4 * max|x''''|`` (Hall & Meyer, *J. Approx. Theory* 16, 1976, for the
complete spline; tests/io/test_truth.py checks the not-a-knot spline against it on a circle), 0.5 mm
in the same turn at 1 Hz (``x'''' = v**4 / R**3``, ``R = 866 m``). A stretch of fewer than four
samples is interpolated linearly.

An epoch whose bracketing samples are more than ``max_gap_s`` apart (default 1.5 times the median sample
interval) has no truth (``no_truth_gap``), nor has one before the first or after the last sample
(``outside_truth_span``); an epoch at a sample's time takes that sample. See :func:`apply_truth` for what
happens to them.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d

from overbound.io._common import RowLog
from overbound.io.geodesy import Reference, enu_errors_along
from overbound.io.gpstime import GPS_EPOCH, PLAUSIBLE_END_US, PLAUSIBLE_START_US
from overbound.io.open import Source, read_text, source_name
from overbound.io.schema import InputError, ReadReport, as_numpy

__all__ = ["INTERPOLATIONS", "Truth", "TruthAnchor", "apply_truth", "read_truth"]

#: ``interpolation=`` choices of :func:`read_truth`.
INTERPOLATIONS = ("cubic", "linear")
#: The default maximum gap, in median sample intervals.
GAP_FACTOR = 1.5
_US = 1_000_000
_GPS_EPOCH_US = (GPS_EPOCH - dt.datetime(1970, 1, 1)) // dt.timedelta(microseconds=1)
_WEEK_US = 604_800 * _US
_OUTSIDE, _GAP = "outside_truth_span", "no_truth_gap"
#: ECEF norms (m) of a truth position: the surface (as Reference.parse_ecef) to beyond GEO; a corrupt
#: number (1e308) is a malformed line, not a spline through infinity.
_ECEF_NORM_M = (6.0e6, 5.0e7)


@dataclass(frozen=True, slots=True)
class TruthAnchor(Reference):
    """The fixed position a reader forms its errors against while :func:`apply_truth` replaces them (the
    truth's first sample); its text names the truth, so the reader's note says what the errors rest on."""

    label: str = ""

    def __str__(self) -> str:
        return self.label


@dataclass(frozen=True, eq=False)
class Truth:
    """A truth trajectory: GPS times (µs since 1970, increasing) and ECEF positions (m, shape (n, 3)).

    ``rows_read``, ``rejected`` (by reason) and ``notes`` say what :func:`read_truth` did with the file.
    """

    source: str
    format: str
    time_us: np.ndarray
    xyz: np.ndarray
    max_gap_s: float
    interpolation: str = "cubic"
    rows_read: int = 0
    rejected: dict[str, int] = dataclasses.field(default_factory=dict)
    notes: tuple[str, ...] = ()
    sha256: str = ""

    @property
    def name(self) -> str:
        return Path(self.source).name

    @property
    def anchor(self) -> TruthAnchor:
        lat, lon, h = pymap3d.ecef2geodetic(*self.xyz[0])
        return TruthAnchor(float(lat), float(lon), float(h), label=str(self))

    def __str__(self) -> str:
        return f"truth trajectory {self.name} (interpolated to each epoch)"

    def read_report(self) -> ReadReport:
        """The file's lines as a reader reports them: read, kept (the samples), rejected by reason."""
        return ReadReport(
            self.source, f"truth {self.format}", self.rows_read, int(self.time_us.size), dict(self.rejected),
            notes=self.notes,
        )  # fmt: skip

    def gaps(self) -> int:
        """Intervals between consecutive samples longer than ``max_gap_s``."""
        return int(np.count_nonzero(np.diff(self.time_us) > self.max_gap_s * _US))

    def summary(self) -> dict:
        """What the errors rest on, for ``summary.json`` and the report."""
        t = pl.Series(self.time_us[[0, -1]]).cast(pl.Datetime("us")).dt.to_string("%Y-%m-%dT%H:%M:%S%.3f")
        step = np.diff(self.time_us) / _US
        return {
            "file": self.name,
            "format": self.format,
            "sha256": self.sha256,
            "samples": int(self.time_us.size),
            "rows_read": self.rows_read,
            "rejected": dict(sorted(self.rejected.items())),
            "span_gpst": [t[0], t[1]],
            "median_interval_s": float(np.median(step)) if step.size else None,
            "max_gap_s": self.max_gap_s,
            "gaps": self.gaps(),
            "interpolation": self.interpolation,
            "notes": list(self.notes),
        }

    def statement(self) -> str:
        """One sentence: the errors are against this trajectory."""
        s = self.summary()
        return (
            f"Errors are against the truth trajectory {s['file']} ({s['format']}, {s['samples']} samples "
            f"{s['span_gpst'][0]} to {s['span_gpst'][1]} GPS time, median interval "
            f"{s['median_interval_s'] or 0:g} s), "
            f"{s['interpolation']} interpolation to each epoch, in the local east-north-up frame of the "
            f"interpolated truth position; gaps longer than {s['max_gap_s']:g} s (their epochs have no "
            f"truth): {s['gaps']}."
        )

    def at(self, time_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The truth's ECEF positions at ``time_us`` (NaN where none) and each epoch's status: ``""``,
        ``"outside_truth_span"`` or ``"no_truth_gap"``."""
        t, xyz = self.time_us, self.xyz
        time_us = np.asarray(time_us, np.int64)
        i = np.searchsorted(t, time_us, side="right") - 1  # the sample at or before each epoch
        outside = (time_us < t[0]) | (time_us > t[-1])
        ic = np.clip(i, 0, t.size - 1)
        exact = ~outside & (t[ic] == time_us)
        nxt = np.clip(ic + 1, 0, t.size - 1)
        gap = ~outside & ~exact & ((t[nxt] - t[ic]) > self.max_gap_s * _US)
        status = np.where(outside, _OUTSIDE, np.where(gap, _GAP, ""))
        out = np.full((time_us.size, 3), np.nan)
        out[exact] = xyz[ic[exact]]
        between = ~outside & ~exact & ~gap
        # stretches of samples without a gap (numbered 0, 1, ... in time): each epoch between two
        # samples lies inside one; the epochs grouped by stretch, each stretch a slice of the samples
        stretch = np.concatenate([[0], np.cumsum(np.diff(t) > self.max_gap_s * _US)])
        first = np.flatnonzero(np.r_[True, np.diff(stretch) != 0])
        last = np.r_[first[1:], t.size]
        idx = np.flatnonzero(between)
        k_of = stretch[ic[idx]]
        order = np.argsort(k_of, kind="stable")
        idx, k_of = idx[order], k_of[order]
        cuts = np.flatnonzero(np.r_[True, np.diff(k_of) != 0, True]) if idx.size else np.zeros(1, np.int64)
        for a, b in itertools.pairwise(cuts):
            s, e = first[k_of[a]], last[k_of[a]]
            out[idx[a:b]] = self._interpolate(t[s:e], xyz[s:e], time_us[idx[a:b]])
        return out, status

    def _interpolate(self, t: np.ndarray, xyz: np.ndarray, at: np.ndarray) -> np.ndarray:
        # seconds from the stretch's start: µs since 1970 squared would lose precision in the spline
        ts, ats = (t - t[0]) / _US, (at - t[0]) / _US
        if self.interpolation == "cubic" and t.size >= 4:
            from scipy.interpolate import CubicSpline  # here: reading without a truth needs no scipy

            return CubicSpline(ts, xyz, axis=0)(ats)
        return np.column_stack([np.interp(ats, ts, xyz[:, j]) for j in range(3)])


def read_truth(
    source: Source,
    *,
    max_gap_s: float | None = None,
    quality: tuple[int, ...] | None = None,
    interpolation: str = "cubic",
    strict: bool = False,
) -> Truth:
    """Read a truth trajectory (the module notes say which files).

    Parameters
    ----------
    source : path or stream.
    max_gap_s : an epoch between samples further apart has no truth; default 1.5 x the median interval.
    quality : RTKLIB ``.pos`` only: the ``Q`` flags kept (default every one but 0, no solution).
    interpolation : ``"cubic"`` (default) or ``"linear"``.
    strict : raise on the first malformed line.

    Raises
    ------
    InputError
        Not an RTKLIB ``.pos`` nor a CSV of the accepted columns, no sample, a time going backwards,
        ``quality`` for a CSV, a ``max_gap_s`` not positive.
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation {interpolation!r}: choose one of {', '.join(INTERPOLATIONS)}")
    name = source_name(source)
    if max_gap_s is not None and not max_gap_s > 0:
        raise InputError(name, f"truth max gap {max_gap_s} s: must be positive")
    from overbound.io.open import sniff

    try:
        fmt = sniff(source)
    except InputError:
        fmt = "csv"  # a CSV whose first line is a comment: the CSV reader names what is missing
    notes: list[str] = []
    if fmt == "rtklib-pos":
        from overbound.io.rtklib import read_pos_positions

        samples, log, system = read_pos_positions(source, strict=strict)
        if system != "GPST":
            notes.append(f"{system} times converted to GPS time")
        samples = _quality(samples, quality, log, notes)
    elif fmt == "csv":
        if quality is not None:
            raise InputError(name, "a truth quality filter applies to RTKLIB .pos files (their Q flag)")
        samples, log = _read_csv(source, name, strict)
    else:
        raise InputError(name, f"a truth trajectory is an RTKLIB .pos or a CSV file, not {fmt}")
    samples = _checked(samples, log)
    time_us = as_numpy(samples["time"]).astype(np.int64)
    step = np.diff(time_us) / _US
    gap = max_gap_s if max_gap_s is not None else (GAP_FACTOR * float(np.median(step)) if step.size else 0.0)
    return Truth(
        source=name,
        format=fmt,
        time_us=time_us,
        xyz=samples.select("x", "y", "z").to_numpy(),
        max_gap_s=gap,
        interpolation=interpolation,
        rows_read=log.rows_read,
        rejected=dict(log.rejected),
        notes=tuple(notes),
        sha256=_digest(source),
    )


def _digest(source: Source) -> str:
    """SHA-256 of the file as stored (the provenance of the inputs takes theirs so), ``""`` for a stream."""
    return hashlib.sha256(Path(source).read_bytes()).hexdigest() if isinstance(source, str | Path) else ""


def _quality(samples: pl.DataFrame, quality, log: RowLog, notes: list[str]) -> pl.DataFrame:
    """The samples whose RTKLIB ``Q`` is kept, the others counted (``quality_not_kept``)."""
    if samples["q"].is_null().all():
        if quality is not None:
            raise InputError(log.source, "a truth quality filter needs the file's Q column")
        return samples
    keep = pl.col("q").is_in(list(quality)) if quality is not None else pl.col("q") != 0
    n_out = samples.height - samples.filter(keep).height
    if n_out:
        log.rejected["quality_not_kept"] += n_out
        what = f"Q in {', '.join(map(str, quality))}" if quality is not None else "Q != 0 (a solution)"
        notes.append(f"{n_out} samples left out: only {what} kept")
    return samples.filter(keep)


def _checked(samples: pl.DataFrame, log: RowLog) -> pl.DataFrame:
    """Positions near the Earth, times strictly increasing (a repeat counted, a step back raised)."""
    norm = (pl.col("x") ** 2 + pl.col("y") ** 2 + pl.col("z") ** 2).sqrt()
    near = norm.is_between(*_ECEF_NORM_M).fill_null(False)  # NaN compares false: not near
    for line in samples.filter(~near)["_line"].to_list():
        log.reject(line, "malformed line: not a position near the Earth (ECEF norm 6,000 to 50,000 km)")
    samples = samples.filter(near)
    if samples.height == 0:
        raise InputError(log.source, "no truth sample (every line rejected or left out)")
    us = as_numpy(samples["time"]).astype(np.int64)
    step = np.diff(us)
    if (back := np.flatnonzero(step < 0)).size:
        i = int(back[0]) + 1
        line = int(samples["_line"][i])
        raise InputError(log.source, f"truth time goes backwards at {samples['time'][i]}", line=line)
    dup = np.concatenate([[False], step == 0])
    for line in samples.filter(pl.Series(dup))["_line"].to_list():
        log.reject(line, "duplicate time: the first sample of that time kept")
    return samples.filter(~pl.Series(dup))


def _read_csv(source: Source, name: str, strict: bool) -> tuple[pl.DataFrame, RowLog]:
    lines = read_text(source).split("\n")
    numbered = [(i, ln.strip()) for i, ln in enumerate(lines, start=1) if ln.strip() and ln.strip()[0] != "#"]
    if not numbered:
        raise InputError(name, "no truth sample (an empty CSV)")
    (head_line, head), rows = numbered[0], numbered[1:]
    cols = [c.strip().lower() for c in head.split(",")]
    time_cols = next((c for c in (("time",), ("gps_seconds",), ("week", "tow")) if set(c) <= set(cols)), None)
    pos_cols = next((c for c in (("lat", "lon", "height"), ("x", "y", "z")) if set(c) <= set(cols)), None)
    if time_cols is None or pos_cols is None:
        raise InputError(
            name,
            f"truth CSV columns {', '.join(cols)[:200]}: need time (or gps_seconds, or week and tow) and "
            "lat, lon, height (or x, y, z)",
            line=head_line,
        )
    log = RowLog(name, strict=strict)
    log.rows_read = len(rows)
    df = pl.DataFrame({"_line": [r[0] for r in rows], "_f": [r[1].split(",") for r in rows]},
                      schema={"_line": pl.Int64, "_f": pl.List(pl.String)})  # fmt: skip
    field = {c: pl.col("_f").list.get(cols.index(c), null_on_oob=True).str.strip_chars() for c in cols}
    num = {c: field[c].cast(pl.Float64, strict=False) for c in (*pos_cols, *time_cols) if c != "time"}
    time = _csv_time(time_cols, field, num)
    us = time.dt.epoch("us")  # a corrupted year is a malformed line, as in every reader
    time = pl.when((us >= PLAUSIBLE_START_US) & (us < PLAUSIBLE_END_US)).then(time).alias("time")
    df = df.select("_line", time, *(num[c].alias(c) for c in pos_cols))
    unusable = [~pl.col(c).is_finite().fill_null(False) for c in pos_cols]  # null, NaN or infinite
    if pos_cols[0] == "lat":
        unusable.append(~pl.col("lat").is_between(-90.0, 90.0).fill_null(False))
    bad = pl.any_horizontal(pl.col("time").is_null(), *unusable)
    for line in df.filter(bad)["_line"].to_list():
        log.reject(line, "malformed line: a time or position field does not parse")
    df = df.filter(~bad)
    if pos_cols == ("lat", "lon", "height"):
        xyz = pymap3d.geodetic2ecef(*(df[c].to_numpy() for c in pos_cols))  # WGS-84
        df = df.drop(pos_cols).with_columns(
            pl.Series(c, v, dtype=pl.Float64) for c, v in zip("xyz", xyz, strict=True)
        )
    return df, log


def _csv_time(time_cols: tuple[str, ...], field: dict, num: dict) -> pl.Expr:
    if time_cols == ("time",):
        return (
            field["time"]
            .str.replace(" ", "T", literal=True)
            .str.strptime(pl.Datetime("us"), "%Y-%m-%dT%H:%M:%S%.f", strict=False)
        )
    if time_cols == ("gps_seconds",):
        us = (num["gps_seconds"] * _US).round(0).cast(pl.Int64, strict=False) + _GPS_EPOCH_US
    else:  # a week or tow out of its range is no time (a NaN or a huge number: null, not an error)
        week, tow = num["week"], num["tow"]
        ok = (week >= 0) & (week <= 9999) & (week == week.floor()) & (tow >= 0) & (tow < _WEEK_US / _US)
        week_us = pl.when(ok).then(week).cast(pl.Int64, strict=False) * _WEEK_US
        us = week_us + (tow * _US).round(0).cast(pl.Int64, strict=False) + _GPS_EPOCH_US
    return pl.from_epoch(us, time_unit="us")


def apply_truth(table: pl.DataFrame, report: ReadReport, truth: Truth) -> tuple[pl.DataFrame, ReadReport]:
    """The errors of ``table`` (read against ``truth.anchor``) taken against ``truth`` instead.

    The positions come back exactly from the anchor-relative errors (``east``, ``north``, ``vpe`` are a
    rotation and a shift of the ECEF position, :func:`pymap3d.enu2ecef` inverts them); each epoch's
    errors are then taken in the east-north-up frame of its interpolated truth position
    (:func:`~overbound.io.geodesy.enu_errors_along`), the frame :mod:`overbound.io.schema` defines the
    errors in ("the local east-north-up frame of the true antenna position"). The frame at the estimate
    would differ by the error over the Earth's radius (1.6e-7 rad per metre): below a micrometre.

    Epochs without truth:

    * before the first or after the last truth sample: removed and counted as rejected,
      ``outside_truth_span``, as ``--start``/``--end`` count ``outside_time_range``: the truth's span is
      the period analysed, and an epoch outside it is no more an unavailable epoch than one outside the
      time range;
    * inside the span, in a gap: kept as a no-solution epoch (errors and PLs NaN, as an unusable error
      makes it, :func:`~overbound.io._common.finalize_epochs`), counted under ``invalidated`` as
      ``no_truth_gap``. It counts as unavailable and breaks continuity: conservative, a gap in the
      truth never raises a KPI. An epoch without a solution stays one and is not counted.

    Raises
    ------
    InputError
        The reader did not use the anchor (its input carries errors, not positions), or the table has
        no ``east``/``north`` to recover the positions from.
    """
    if not any(str(truth) in n for n in report.notes) or not {"east", "north"} <= set(table.columns):
        raise InputError(
            report.source,
            f"{report.format} input: its errors are not formed from positions here, so a truth trajectory "
            "cannot apply (--truth needs positions: RTKLIB .pos, UBX, SBF, NMEA, SBP, CSV/Parquet with "
            "lat/lon/height, gLAB with OUTPUT lines)",
        )
    anchor = truth.anchor
    times = as_numpy(table["time"])
    truth_xyz, status = truth.at(times)
    keep = status != _OUTSIDE
    if times.size and not keep.any():
        span = " to ".join(str(t)[:23] for t in (times.min(), times.max()))
        raise InputError(
            report.source,
            f"no epoch inside the span of the truth trajectory {truth} ({span} outside it; GPS time, "
            "or UTC labelled as GPS time?)",
        )
    report = report.keep(keep, _OUTSIDE)  # the invalidated rows among those removed recounted
    table, truth_xyz, status = table.filter(pl.Series(keep)), truth_xyz[keep], status[keep]
    east, north, up = (as_numpy(table[c]).astype(float) for c in ("east", "north", "vpe"))
    solved = np.isfinite(east) & np.isfinite(north) & np.isfinite(up)
    gap = solved & (status == _GAP)
    ok = solved & ~gap
    x, y, z = pymap3d.enu2ecef(east[ok], north[ok], up[ok], anchor.lat_deg, anchor.lon_deg, anchor.height_m)
    e = np.full(table.height, np.nan)
    n, u = e.copy(), e.copy()
    e[ok], n[ok], u[ok] = enu_errors_along(x, y, z, *truth_xyz[ok].T)
    nan = np.where(gap, np.nan, 1.0)
    cols = {"east": e, "north": n, "vpe": u, "hpe": np.hypot(e, n)}
    cols |= {c: as_numpy(table[c]) * nan for c in ("hpl", "vpl")}
    table = table.with_columns(pl.Series(k, v, dtype=pl.Float64) for k, v in cols.items())
    n_out, n_gap = int(np.count_nonzero(~keep)), int(np.count_nonzero(gap))
    invalidated = {**report.invalidated, **({_GAP: n_gap} if n_gap else {})}
    rows, reasons = report.invalid_rows, report.invalid_reasons
    if rows is not None and reasons is not None and n_gap:  # for a time window applied afterwards
        at = np.flatnonzero(gap)
        rows, reasons = np.concatenate([rows, at]), np.concatenate([reasons, np.full(at.size, _GAP, object)])
    note = (
        f"errors against {truth}: {n_out} epochs outside its span removed, {n_gap} epochs in its gaps "
        "(no truth) made no-solution epochs"
    )
    first_bad = report.first_bad or (f"{_GAP}: epoch {table['time'][int(np.argmax(gap))]}" if n_gap else "")
    return table, dataclasses.replace(
        report, invalidated=invalidated, first_bad=first_bad,
        notes=(*report.notes, note), invalid_rows=rows, invalid_reasons=reasons,
    )  # fmt: skip
