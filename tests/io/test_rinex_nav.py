"""GPS broadcast ephemerides: RINEX 2 / 3 reading, ephemeris selection, orbit and clock (IS-GPS-200),
checked line by line, against gLAB v6 and against IGS precise orbits (tests/data/rinex, PROVENANCE.md)."""

from __future__ import annotations

import datetime as dt
import gzip
import math
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.rinex_nav import (
    FIELDS,
    GPS_OMEGA_E,
    SPEED_OF_LIGHT,
    broadcast_state,
    clock_at,
    ephemeris_elements,
    read_rinex_nav,
    rotate_earth,
    select_ephemeris,
    state_at,
)
from overbound.io.schema import InputError
from overbound.io.sp3 import read_sp3

DATA = Path(__file__).resolve().parents[1] / "data" / "rinex"
BRDC = DATA / "brdc0140_cut.19n.gz"  # RINEX 2, G04 G07 G08 G10 G18 G21, 2019-01-14
MIXED = DATA / "ESBC00DNK_cut_MN.rnx.gz"  # RINEX 3.05 mixed: 4 GPS satellites, 2 records of C E J R S
SP3 = DATA / "igs20361_cut.sp3.gz"
GLAB = DATA / "glab_satpvt_brdc.txt.gz"
_EPOCH = dt.datetime(1970, 1, 1)
_US = 1_000_000


def _lines(path: Path) -> list[str]:
    return gzip.decompress(path.read_bytes()).decode().splitlines()


def _slow_records(path: Path) -> list[tuple[int, dt.datetime, list[float]]]:
    """Independent reading: (PRN, toc, the 29 numbers) of each GPS record, with Python's float()."""
    lines = _lines(path)
    body = next(i for i, s in enumerate(lines) if "END OF HEADER" in s) + 1
    v3 = float(lines[0][:9]) >= 3
    out = []
    i = body
    while i < len(lines):
        s = lines[i]
        n_lines = 1 + next((k for k, t in enumerate(lines[i + 1 :]) if t[:3].strip()), len(lines) - i - 1)
        if v3 and s[0] != "G":
            i += n_lines
            continue
        if v3:
            prn, toc = int(s[1:3]), dt.datetime(*(int(x) for x in s[4:23].split()))
            nums = [s[23 + 19 * k : 42 + 19 * k] for k in range(3)]
            nums += [t[4 + 19 * k : 23 + 19 * k] for t in lines[i + 1 : i + 8] for k in range(4)]
        else:
            f = s[:22].split()
            toc = dt.datetime(2000 + int(f[1]), *(int(x) for x in f[2:6])) + dt.timedelta(seconds=float(f[6]))
            prn = int(f[0])
            nums = [s[22 + 19 * k : 41 + 19 * k] for k in range(3)]
            nums += [t[3 + 19 * k : 22 + 19 * k] for t in lines[i + 1 : i + 8] for k in range(4)]
        values = [float(x.replace("D", "E")) if x.strip() else math.nan for x in nums[: len(FIELDS)]]
        out.append((prn, toc, values))
        i += n_lines
    return sorted(out, key=lambda r: (r[0], r[1]))


def _glab() -> dict[str, np.ndarray]:
    """gLAB's SATPVT lines: year doy sod prn x y z clock(m) iod health."""
    rows = [s.split() for s in _lines(GLAB) if not s.startswith("#")]
    day = np.array([(dt.datetime(int(r[0]), 1, 1) - _EPOCH).days + int(r[1]) - 1 for r in rows])
    return {
        "time": (day * 86_400 + np.array([round(float(r[2])) for r in rows])) * _US,
        "prn": np.array([int(r[3]) for r in rows]),
        "xyz": np.array([[float(x) for x in r[4:7]] for r in rows]),
        "clock": np.array([float(r[7]) for r in rows]),
        "iod": np.array([int(r[8]) for r in rows]),
        "healthy": np.array([r[9].startswith("H") for r in rows]),
    }


@pytest.mark.parametrize("path", [BRDC, MIXED], ids=["rinex2", "rinex3-mixed"])
def test_records_read_like_line_by_line(path):
    expected = _slow_records(path)
    eph, report = read_rinex_nav(path)
    t = eph.table
    assert t.height == len(expected) == report.rows_kept == report.rows_read
    assert t["prn"].to_list() == [r[0] for r in expected]
    assert t["toc"].to_list() == [r[1] for r in expected]
    for k, name in enumerate(FIELDS):
        want = np.array([r[2][k] for r in expected])
        got = t[name].to_numpy().astype(float)
        assert np.array_equal(got, want) if name != "fit_interval" else np.allclose(got, want), name
    assert report.rejected == {}


def test_rinex2_header_and_absolute_times():
    eph, _ = read_rinex_nav(BRDC)
    h = eph.header
    assert h.version == 2.0 and h.leap_seconds == 18
    assert h.ion_alpha == (0.7451e-08, -0.1490e-07, -0.5960e-07, 0.1192e-06)
    assert h.ion_beta == (0.8806e05, -0.4915e05, -0.1966e06, 0.3277e06)
    assert h.delta_utc == (-0.186264514923e-08, -0.266453525910e-14, 233472, 2036)
    t = eph.table
    week_start = dt.datetime(1980, 1, 6) + dt.timedelta(weeks=2036)
    assert t["toe_time"].to_list() == [week_start + dt.timedelta(seconds=s) for s in t["toe"].to_list()]
    assert t["ttx_time"].to_list() == [week_start + dt.timedelta(seconds=s) for s in t["ttx"].to_list()]
    assert set(t["sat"]) == {"G04", "G07", "G08", "G10", "G18", "G21"}
    assert (t.filter(pl.col("prn") == 4)["health"] != 0).all()  # G04 was set unhealthy all day


def test_mixed_file_keeps_gps_and_counts_the_others():
    eph, report = read_rinex_nav(MIXED)
    assert eph.other_systems == {"C": 2, "E": 2, "J": 2, "R": 2, "S": 2}
    assert set(eph.table["sat"]) == {"G01", "G02", "G05", "G13"}
    assert eph.header.ion_alpha == (4.6566e-09, 1.4901e-08, -5.9605e-08, -1.1921e-07)
    assert eph.header.delta_utc == (9.3132257462e-10, 2.664535259e-15, 589824, 2111)
    assert "C: 2, E: 2, J: 2, R: 2, S: 2" in report.notes[1]


def test_positions_clocks_and_selection_agree_with_glab():
    eph, _ = read_rinex_nav(BRDC)
    g = _glab()
    rows = select_ephemeris(eph.table, g["prn"], g["time"], healthy_only=False)
    assert (rows >= 0).all()
    assert np.array_equal(eph.table["iode"].to_numpy()[rows], g["iod"])  # gLAB's choice of record
    st = broadcast_state(eph.table, rows, g["time"])
    assert np.abs(st.position - g["xyz"]).max() < 1e-3  # gLAB prints 0.1 mm
    # gLAB's SATPVT clock is af0 + af1 dt + af2 dt^2, without the relativistic term.
    assert np.abs((st.clock - st.relativistic) * SPEED_OF_LIGHT - g["clock"]).max() < 2e-6
    healthy = select_ephemeris(eph.table, g["prn"], g["time"])
    assert np.array_equal(healthy >= 0, g["healthy"])  # unhealthy G04 has no usable record


def test_selection_rules():
    eph, _ = read_rinex_nav(BRDC)
    t = eph.table
    g07 = t.filter(pl.col("prn") == 7)
    toe = g07["toe_time"][3]
    at = int((toe - _EPOCH) / dt.timedelta(microseconds=1))
    row = select_ephemeris(t, 7, at)
    assert t["toe_time"][int(row)] == toe and t["ttx_time"][int(row)] <= toe
    later = select_ephemeris(t, 7, at + 3 * 3600 * _US)  # a newer record has been transmitted since
    assert t["ttx_time"][int(later)] > t["ttx_time"][int(row)]
    assert select_ephemeris(t, 7, at, iode=int(t["iode"][int(later)])) == -1  # not yet transmitted
    assert select_ephemeris(t, 7, at, iode=int(t["iode"][int(row)])) == row
    first_ttx = g07["ttx_time"].min()
    before = int((first_ttx - _EPOCH) / dt.timedelta(microseconds=1)) - _US
    assert select_ephemeris(t, 7, before) == -1
    last_toe = int((g07["toe_time"].max() - _EPOCH) / dt.timedelta(microseconds=1))
    assert select_ephemeris(t, 7, last_toe + 2 * 3600 * _US) >= 0  # fit interval 4 h: +-2 h
    assert select_ephemeris(t, 7, last_toe + 2 * 3600 * _US + _US) == -1
    assert select_ephemeris(t, 5, at) == -1  # no record for that PRN
    grid = select_ephemeris(t, np.array([[7], [8]]), np.array([at, at + _US]))
    assert grid.shape == (2, 2) and (grid >= 0).all()


def test_broadcast_orbits_agree_with_igs_final_orbits():
    """IS-GPS-200 positions against the IGS final SP3 of the same day: broadcast orbits of 2019 are good to
    about 1-2 m (plus the antenna-offset difference of the two products), clocks to a few ns."""
    eph, _ = read_rinex_nav(BRDC)
    sp3, _ = read_sp3(SP3)
    prn = np.array([int(s[1:]) for s in sp3.sats])
    tt, pp = np.meshgrid(sp3.time, prn, indexing="ij")
    rows = select_ephemeris(eph.table, pp, tt)
    ok = rows >= 0
    assert ok[:, sp3.sat_index(["G04"])].sum() == 0 and ok.mean() > 0.8
    st = broadcast_state(eph.table, rows[ok], tt[ok])
    err = np.linalg.norm(st.position - sp3.position[ok], axis=1)
    assert np.median(err) < 2.0 and err.max() < 5.0
    clock = st.clock - st.relativistic  # SP3 clocks exclude the periodic relativistic term
    diff = clock - sp3.clock[ok]
    epoch = np.broadcast_to(np.arange(len(sp3.time))[:, None], ok.shape)[ok]
    fin = np.isfinite(diff)
    offset = np.array([np.median(diff[fin & (epoch == k)]) for k in range(len(sp3.time))])
    resid = (diff - offset[epoch])[fin]
    assert np.sqrt(np.mean(resid**2)) < 5e-9 and np.abs(offset).max() < 20e-9


def test_relativistic_term_is_minus_two_r_dot_v_over_c2():
    eph, _ = read_rinex_nav(BRDC)
    rows = np.flatnonzero(eph.table["health"].to_numpy() == 0)
    t = eph.table["toe_time"].dt.epoch("us").to_numpy()[rows] + 1234 * _US
    st = broadcast_state(eph.table, rows, t)
    h = 0.5
    ahead = broadcast_state(eph.table, rows, t, h).position
    behind = broadcast_state(eph.table, rows, t, -h).position
    v_ecef = (ahead - behind) / (2 * h)
    v_inertial = v_ecef + np.cross([0.0, 0.0, GPS_OMEGA_E], st.position)
    expected = -2 * np.sum(st.position * v_inertial, axis=1) / SPEED_OF_LIGHT**2
    assert np.abs(st.relativistic).max() > 5e-9  # eccentric orbits: the term matters
    assert np.abs(st.relativistic - expected).max() < 0.1e-9  # the harmonic corrections differ a little


def test_rotate_earth():
    p = np.array([[2.0e7, 1.0e7, 1.5e7], [-1.2e7, 2.2e7, -0.5e7]])
    tau = np.array([0.07, 0.08])
    r = rotate_earth(p, tau)
    assert np.allclose(np.linalg.norm(r, axis=1), np.linalg.norm(p, axis=1), rtol=0, atol=1e-6)
    assert np.array_equal(r[:, 2], p[:, 2])
    angle = np.arctan2(p[:, 1], p[:, 0]) - np.arctan2(r[:, 1], r[:, 0])  # the frame turned east
    assert np.allclose(angle, GPS_OMEGA_E * tau, rtol=1e-12)
    assert np.array_equal(rotate_earth(p, 0.0), p)


def test_bad_records_are_counted(tmp_path):
    lines = _lines(BRDC)
    body = next(i for i, s in enumerate(lines) if "END OF HEADER" in s) + 1
    r1, r2, r3, r4 = (body + 8 * k for k in (1, 3, 5, 7))
    lines[r2 + 1] = lines[r2 + 1][:30] + "X" + lines[r2 + 1][31:]  # unreadable Crs
    lines[r3 + 2] = lines[r3 + 2][:60] + " " * 19  # blank sqrt(A)
    lines[r4 + 2] = lines[r4 + 2][:22] + " 0.150000000000D+01" + lines[r4 + 2][41:]  # e = 1.5
    del lines[r1 + 7]  # a record one line short
    path = tmp_path / "bad.19n"
    path.write_text("\n".join(lines) + "\n")
    eph, report = read_rinex_nav(path)
    rej = eph.rejected
    assert dict(zip(rej["reason"], rej["line"], strict=True)) == {
        "record_length": r1 + 1,
        "bad_number": r2,
        "missing_field": r3,
        "implausible_orbit": r4,
    }
    assert eph.table.height == len(_slow_records(BRDC)) - 4 and report.n_rejected == 4
    with pytest.raises(InputError, match=rf"bad.19n:{r1 + 1}: GPS record without exactly 8 lines"):
        read_rinex_nav(path, strict=True)


def test_several_files_merge_and_repeats_are_dropped(tmp_path):
    copy = tmp_path / "copy.19n.gz"
    copy.write_bytes(BRDC.read_bytes())
    one, _ = read_rinex_nav(BRDC)
    two, report = read_rinex_nav([BRDC, copy])
    assert two.table.drop("file", "line").equals(one.table.drop("file", "line"))
    assert report.rejected == {"duplicate": one.table.height}
    assert set(two.rejected["file"]) == {str(copy)}


def test_unix_compress_input(tmp_path):
    """IGS archives ship RINEX 2 navigation files as ``.Z`` (LZW); ``hatanaka`` expands them."""
    import ncompress

    z = tmp_path / "brdc0140.19n.Z"
    z.write_bytes(ncompress.compress(gzip.decompress(BRDC.read_bytes())))
    eph, _ = read_rinex_nav(z)
    assert eph.table.drop("file").equals(read_rinex_nav(BRDC)[0].table.drop("file"))


def test_bad_inputs(tmp_path):
    lines = _lines(BRDC)
    raw = gzip.compress("\n".join(lines).encode())
    cut = tmp_path / "cut.19n.gz"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputError, match=r"cut\.19n\.gz: truncated or corrupt gzip"):
        read_rinex_nav(cut)
    glo = tmp_path / "glo.19g"
    glo.write_text("\n".join([lines[0][:20] + "G" + lines[0][21:], *lines[1:]]))
    with pytest.raises(InputError, match="RINEX 2 GLONASS navigation file: no GPS ephemerides"):
        read_rinex_nav(glo)
    v4 = tmp_path / "v4.rnx"
    v4.write_text("\n".join([f"{'4.00':>9}" + lines[0][9:], *lines[1:]]))
    with pytest.raises(InputError, match=r"v4\.rnx:1: RINEX navigation version 4.00 not supported"):
        read_rinex_nav(v4)
    obs = DATA / "SYNT0140_cut.19o.gz"
    with pytest.raises(InputError, match="expected navigation data"):
        read_rinex_nav(obs)
    headless = tmp_path / "headless.19n"
    headless.write_text("\n".join(lines[:5]))
    with pytest.raises(InputError, match="no END OF HEADER"):
        read_rinex_nav(headless)


def test_gathered_elements_give_broadcast_state_bit_for_bit():
    """state_at/clock_at on elements gathered once (the engine's fast path) equal broadcast_state exactly."""
    eph, _ = read_rinex_nav(BRDC)
    rows = np.flatnonzero(eph.table["health"].to_numpy() == 0)
    t = eph.table["toe_time"].dt.epoch("us").to_numpy()[rows] + 1234 * _US
    off = np.linspace(-0.09, -0.06, rows.size)  # transmission-time offsets
    ref = broadcast_state(eph.table, rows, t, off)
    g = ephemeris_elements(eph.table, rows)
    st = state_at(g, t, off)
    np.testing.assert_array_equal(st.position, ref.position)
    np.testing.assert_array_equal(st.clock, ref.clock)
    np.testing.assert_array_equal(clock_at(g, t, off), ref.clock)
    with pytest.raises(ValueError, match="rows must be >= 0"):
        ephemeris_elements(eph.table, np.array([-1]))


# --------------------------------------------------------------------------- issue 13: each record once

BAD = DATA / "bad"  # damaged copies (PROVENANCE.md)


def test_non_finite_fields_and_out_of_span_years_reject_each_record_once():
    """Infinity, NaN, a NUL byte in a number and the year 2079: four records, four rejections."""
    path = BAD / "nav-nonfinite-fields.19n"
    eph, report = read_rinex_nav(path)
    assert (report.rows_read, report.rows_kept) == (6, 2) and report.unaccounted == 0
    assert report.rejected == {"bad_number": 3, "time_out_of_range": 1}
    assert eph.rejected.select("line", "reason").rows() == [
        (18, "bad_number"),
        (26, "bad_number"),
        (34, "bad_number"),
        (42, "time_out_of_range"),
    ]
    assert eph.table["prn"].to_list() == [4, 21]
    assert np.isfinite(eph.table.select(pl.col(pl.Float64)).to_numpy()).all()


def _record_file(tmp_path: Path, path: Path, edit) -> tuple:
    lines = _lines(path)
    body = next(i for i, s in enumerate(lines) if "END OF HEADER" in s) + 1
    first = body + 8 * 3 if path == BRDC else next(i for i in range(body, len(lines)) if lines[i][0] == "G")
    edit(lines, first)
    out = tmp_path / path.name.replace(".gz", "")
    out.write_text("\n".join(lines) + "\n")
    return first + 1, *read_rinex_nav(out)


def _field(lines: list[str], i: int, k: int, text: str, v3: bool = False) -> None:
    c = (23 if v3 else 22) + 19 * k if lines[i][:3].strip() else (4 if v3 else 3) + 19 * k
    lines[i] = lines[i][:c] + text.rjust(19) + lines[i][c + 19 :]


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda s, i: _field(s, i, 1, "Infinity"), "bad_number"),
        (lambda s, i: _field(s, i + 6, 3, "-inf"), "bad_number"),  # IODC
        (lambda s, i: _field(s, i + 4, 0, "nan"), "bad_number"),
        (lambda s, i: _field(s, i + 5, 2, "9e99"), "bad_number"),  # week beyond 32 bits
        (lambda s, i: _field(s, i + 3, 0, "1e300"), "time_out_of_range"),  # toe
        (lambda s, i: _field(s, i + 7, 0, "1e300"), "time_out_of_range"),  # transmission time
        # a bad epoch and a bad number in one record: rejected once, for the first
        (lambda s, i: (_field(s, i, 1, "1.0X"), s.__setitem__(i, s[i][:9] + "99" + s[i][11:])), "bad_epoch"),
        (lambda s, i: s.__setitem__(i, s[i][:3] + "79" + s[i][5:]), "time_out_of_range"),  # 2079
        (lambda s, i: s.__setitem__(i, s[i][:3] + "18" + s[i][5:]), "toc_toe_mismatch"),  # 2018
        (lambda s, i: s.__setitem__(i, s[i][:3] + "  " + s[i][5:]), "bad_epoch"),  # blank year
        (lambda s, i: s.__setitem__(i + 2, s[i + 2][:60] + "00" + s[i + 2][60:]), "line_too_long"),
        (lambda s, i: s.__setitem__(i + 1, s[i + 1][:40] + "\x00" + s[i + 1][41:]), "bad_number"),
    ],
    ids=[
        "inf",
        "minus-inf",
        "nan",
        "huge-int",
        "toe",
        "ttx",
        "epoch-and-number",
        "2079",
        "2018",
        "blank-year",
        "long-line",
        "nul",
    ],
)
def test_a_damaged_rinex2_record_is_read_once_and_rejected_once(tmp_path, edit, reason):
    line, eph, report = _record_file(tmp_path, BRDC, edit)
    assert report.rows_read == 79 and report.rows_kept == 78 and report.unaccounted == 0
    assert report.rejected == {reason: 1} and eph.rejected["line"].to_list() == [line]


@pytest.mark.parametrize(
    ("edit", "reason", "read"),
    [
        (lambda s, i: s.__setitem__(i, s[i][:4] + "1979" + s[i][8:]), "time_out_of_range", 31),
        (lambda s, i: s.__setitem__(i, s[i][:4] + "9999" + s[i][8:]), "time_out_of_range", 31),
        (lambda s, i: s.__setitem__(i, s[i][:4] + "0000" + s[i][8:]), "time_out_of_range", 31),
        (lambda s, i: s.__setitem__(i, "X" + s[i][1:]), "unknown_system", 31),
        (lambda s, i: s.__setitem__(i, "\x00" + s[i][1:]), "unknown_system", 31),
        (lambda s, i: _field(s, i + 2, 3, "NaN", v3=True), "bad_number", 31),
    ],
    ids=["1979", "9999", "0000", "system-X", "system-NUL", "nan"],
)
def test_a_damaged_rinex3_record_is_read_once_and_rejected_once(tmp_path, edit, reason, read):
    line, eph, report = _record_file(tmp_path, MIXED, edit)
    assert report.rows_read == read and report.rows_kept == 30 and report.unaccounted == 0
    assert report.rejected == {reason: 1} and eph.rejected["line"].to_list() == [line]
    assert report.first_bad.endswith(f":{line}: {reason}")
