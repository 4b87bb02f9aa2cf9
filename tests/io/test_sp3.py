"""SP3 reader and interpolation: IGS and MGEX cuts (tests/data/rinex, PROVENANCE.md), gLAB v6's
interpolation of the same file, held-out epochs, and damaged copies."""

from __future__ import annotations

import dataclasses
import datetime as dt
import gzip
import math
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from overbound.io.gpstime import PLAUSIBLE_END
from overbound.io.schema import InputError
from overbound.io.sp3 import interpolate_clock, interpolate_position, read_sp3

DATA = Path(__file__).resolve().parents[1] / "data" / "rinex"
IGS = DATA / "igs20361_cut.sp3.gz"  # G04 G07 G08 G10 G18 G21, 96 epochs; G04/G18 miss clocks
MGEX = DATA / "GRG0MGXFIN_cut.sp3.gz"  # E01 E02 G01 G02 R01 R02, 12 epochs
GLAB = DATA / "glab_satpvt_sp3.txt.gz"
_EPOCH = dt.datetime(1970, 1, 1)
_US = 1_000_000


def _lines(path: Path) -> list[str]:
    return gzip.decompress(path.read_bytes()).decode().splitlines()


def _write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _slow_read(path: Path) -> dict[tuple[dt.datetime, str], tuple[float, float, float, float]]:
    """Independent reading: (epoch, satellite) -> x, y, z (m), clock (s); exact decimal scaling."""
    out, t = {}, None
    for s in _lines(path):
        if s.startswith("*"):
            f = s[1:].split()
            t = dt.datetime(*(int(x) for x in f[:5])) + dt.timedelta(seconds=float(f[5]))
        elif s.startswith("P"):
            xyz = [float(Decimal(s[4 + 14 * k : 18 + 14 * k]) * 1000) for k in range(3)]
            clk = Decimal(s[46:60])
            out[(t, s[1:4])] = (*xyz, math.nan if clk >= 999999 else float(clk * Decimal("1e-6")))
    return out


def _as_time(t: dt.datetime) -> int:
    return (t - _EPOCH) // dt.timedelta(microseconds=1)


@pytest.mark.parametrize("path", [IGS, MGEX], ids=["igs", "mgex"])
def test_reads_like_line_by_line(path):
    expected = _slow_read(path)
    sp3, report = read_sp3(path)
    n, m = sp3.clock.shape
    assert n * m == len(expected) == report.rows_read
    times = sorted({k[0] for k in expected})
    assert sp3.time.tolist() == [_as_time(t) for t in times]
    assert sorted(sp3.sats) == sorted({k[1] for k in expected})
    for (t, sat), (x, y, z, c) in expected.items():
        i, j = times.index(t), sp3.sats.index(sat)
        assert tuple(sp3.position[i, j]) == (x, y, z)
        assert sp3.clock[i, j] == c or (math.isnan(c) and math.isnan(sp3.clock[i, j]))


def test_header_missing_clocks_and_frame():
    sp3, report = read_sp3(IGS)
    h = sp3.header
    assert (h.version, h.pv_flag, h.coordinate_system, h.orbit_type, h.agency) == (
        "c",
        "P",
        "IGS14",
        "HLM",
        "IGS",
    )
    assert h.time_system == "GPS" and h.interval == 900.0 and h.n_epochs_declared == 96
    missing = int(np.isnan(sp3.clock).sum())
    assert missing > 0 and report.invalidated == {"missing_clock": missing}
    assert np.isnan(sp3.clock[:, sp3.sat_index(["G04"])[0]]).sum() > 30  # unhealthy, unclocked satellite
    assert np.isfinite(sp3.position).all() and report.rejected == {}
    frame = sp3.to_frame()
    assert frame.height == sp3.clock.size and frame["time"][0] == dt.datetime(2019, 1, 14)
    mgex, _ = read_sp3(MGEX)
    assert mgex.header.coordinate_system == "IGb14" and {s[0] for s in mgex.sats} == {"E", "G", "R"}


def test_interpolation_reproduces_held_out_epochs():
    """Every fourth interior epoch removed: degree-10 Lagrange on the rest gives them back to < 1 cm."""
    sp3, _ = read_sp3(IGS)
    n, m = sp3.clock.shape
    held = np.arange(7, n - 7, 4)
    keep = np.setdiff1d(np.arange(n), held)
    thin = dataclasses.replace(
        sp3, time=sp3.time[keep], position=sp3.position[keep], clock=sp3.clock[keep], flags=sp3.flags[keep]
    )
    t, col = np.meshgrid(sp3.time[held], np.arange(m), indexing="ij")
    err = np.linalg.norm(interpolate_position(thin, col, t) - sp3.position[held], axis=-1)
    assert err.max() < 0.01
    low = np.linalg.norm(interpolate_position(thin, col, t, degree=6) - sp3.position[held], axis=-1)
    assert np.median(low) > 10 * np.median(err)  # the degree matters at 15-min sampling


def test_interpolation_at_nodes_outside_and_across_missing_values():
    sp3, _ = read_sp3(IGS)
    j = sp3.sat_index(["G07"])[0]
    assert np.allclose(interpolate_position(sp3, j, sp3.time), sp3.position[:, j], rtol=0, atol=1e-6)
    assert np.isnan(interpolate_position(sp3, "G07", sp3.time[0] - _US)).all()
    assert np.isnan(interpolate_position(sp3, "G07", sp3.time[-1] + _US)).all()
    assert np.isnan(interpolate_position(sp3, "G99", sp3.time[5])).all()
    assert np.isfinite(interpolate_position(sp3, "G07", sp3.time[-1])).all()
    holed = dataclasses.replace(sp3, position=sp3.position.copy())
    holed.position[40, j] = np.nan
    t = sp3.time[40] + 300 * _US
    assert np.isnan(interpolate_position(holed, "G07", t)).all()
    far = interpolate_position(holed, "G07", sp3.time[60])  # the hole is out of its window
    assert np.isfinite(far).all()
    # a float offset moves the time by less than a microsecond
    p0 = interpolate_position(sp3, "G07", t)
    p1 = interpolate_position(sp3, "G07", t, 0.5e-6)
    assert 1e-4 < np.linalg.norm(p1 - p0) < 3e-3  # ~4 km/s x 0.5 us
    c = interpolate_clock(sp3, "G07", sp3.time[40] + 450 * _US)
    assert c == pytest.approx((sp3.clock[40, j] + sp3.clock[41, j]) / 2, rel=0, abs=1e-18)
    g04 = sp3.sat_index(["G04"])[0]
    k = int(np.flatnonzero(np.isnan(sp3.clock[:-1, g04]))[0])
    assert np.isnan(interpolate_clock(sp3, "G04", sp3.time[k] + 450 * _US))  # a missing neighbour


def test_interpolation_agrees_with_glab():
    rows = [s.split() for s in _lines(GLAB) if not s.startswith("#")]
    day = np.array([(dt.datetime(int(r[0]), 1, 1) - _EPOCH).days + int(r[1]) - 1 for r in rows])
    t = (day * 86_400 + np.array([round(float(r[2])) for r in rows])) * _US
    sat = np.array([f"G{int(r[3]):02d}" for r in rows])
    xyz = np.array([[float(x) for x in r[4:7]] for r in rows])
    clock = np.array([float(r[7]) for r in rows])
    sp3, _ = read_sp3(IGS)
    off_grid = (t - sp3.time[0]) % (900 * _US) != 0
    assert off_grid.mean() > 0.8
    pos = interpolate_position(sp3, sat, t)
    assert np.abs(pos - xyz).max() < 3e-3  # same degree; the window of 11 epochs may differ by one
    ours = interpolate_clock(sp3, sat, t) * 299_792_458.0
    both = np.isfinite(ours)
    assert (
        both.mean() > 0.8 and np.abs(ours - clock)[both].max() < 2e-6
    )  # linear, like gLAB (printed to 1 um)


def test_velocity_records(tmp_path):
    lines = _lines(IGS)
    i = next(k for k, s in enumerate(lines) if s.startswith("PG07"))
    lines.insert(i + 1, "VG07  12345.678901 -23456.789012   3456.789012      0.123456")
    sp3, report = read_sp3(_write(tmp_path, "pv.sp3", lines))
    j = sp3.sat_index(["G07"])[0]
    assert sp3.velocity is not None and report.rejected == {}
    assert tuple(sp3.velocity[0, j]) == (1234.5678901, -2345.6789012, 345.6789012)  # dm/s -> m/s
    assert sp3.clock_rate[0, j] == 1.23456e-11  # 1e-4 us/s -> s/s
    assert np.isnan(sp3.velocity[1:, j]).all() and np.isnan(sp3.velocity[:, j - 1]).all()
    assert read_sp3(IGS)[0].velocity is None


def test_several_days_merge(tmp_path):
    lines = _lines(IGS)
    stars = [i for i, s in enumerate(lines) if s.startswith("*")]
    head = lines[: stars[0]]
    first = _write(tmp_path, "a.sp3", head + lines[stars[0] : stars[48]] + ["EOF"])
    second = _write(tmp_path, "b.sp3", head + lines[stars[48] :])
    whole, _ = read_sp3(IGS)
    merged, report = read_sp3([second, first])
    assert np.array_equal(merged.time, whole.time)
    assert np.array_equal(merged.position, whole.position, equal_nan=True)
    assert np.array_equal(merged.clock, whole.clock, equal_nan=True)
    assert report.rows_read == whole.clock.size


def test_bad_lines_and_files(tmp_path):
    lines = _lines(IGS)
    stars = [i for i, s in enumerate(lines) if s.startswith("*")]
    p1, p2, p3 = stars[2] + 1, stars[3] + 2, stars[4] + 3
    lines[p1] = lines[p1][:10] + "ABC" + lines[p1][13:]  # unreadable x
    lines[p2] = "PG31" + lines[p2][4:]  # not in the header list
    lines[p3] = lines[p3][:4] + f"{0.0:14.6f}" * 3 + lines[p3][46:]  # position 0.000000: missing
    path = _write(tmp_path, "bad.sp3", lines)
    sp3, report = read_sp3(path)
    assert report.rejected == {"bad_record": 1, "unlisted_satellite": 1}
    assert sp3.rejected.select("line", "reason").rows() == [
        (p1 + 1, "bad_record"),
        (p2 + 1, "unlisted_satellite"),
    ]
    assert report.invalidated["missing_position"] == 1
    assert np.isnan(sp3.position).any(axis=-1).sum() == 3
    with pytest.raises(InputError, match=rf"bad\.sp3:{p1 + 1}: unreadable position/velocity line"):
        read_sp3(path, strict=True)
    with pytest.raises(InputError, match="SP3 version 'e' not supported"):
        read_sp3(_write(tmp_path, "v.sp3", ["#eP" + lines[0][3:], *lines[1:]]))
    with pytest.raises(InputError, match="not an SP3 file"):
        read_sp3(DATA / "brdc0140_cut.19n.gz")
    with pytest.raises(InputError, match="no epoch line"):
        read_sp3(_write(tmp_path, "head.sp3", lines[: stars[0]]))
    raw = IGS.read_bytes()
    cut = tmp_path / "cut.sp3.gz"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputError, match="truncated or corrupt gzip"):
        read_sp3(cut)


def test_clock_query_just_before_an_epoch_is_interpolated_not_nan():
    """A transmission time (an SP3 epoch minus ~70 ms) falls in the interval before that epoch."""
    sp, _ = read_sp3(IGS)
    col = int(np.flatnonzero(np.isfinite(sp.clock[9]) & np.isfinite(sp.clock[10]))[0])
    t = sp.time[10]
    before = interpolate_clock(sp, np.array([col]), np.array([t]), -0.07)[0]
    c0, c1 = sp.clock[9, col], sp.clock[10, col]
    dt = (sp.time[10] - sp.time[9]) / 1e6
    assert before == pytest.approx(c1 + (c0 - c1) * 0.07 / dt, rel=0, abs=1e-15)


# --------------------------------------------------------------------------- issue 13: every line counted

BAD = DATA / "bad"  # damaged copies (PROVENANCE.md)


def _epoch_lines(lines: list[str]) -> list[int]:
    return [i for i, s in enumerate(lines) if s.startswith("*")]


def test_a_changed_epoch_hour_is_rejected_and_overwrites_nothing():
    """02:30 written 00:30: its six lines are rejected at the epoch line, the real 00:30 stays."""
    path = BAD / "sp3-hour-changed.sp3"
    sp3, report = read_sp3(path)
    assert (report.rows_read, report.rows_kept, report.rejected) == (72, 66, {"duplicate_epoch": 6})
    assert report.unaccounted == 0 and report.first_bad == f"{path}:94: duplicate_epoch"
    assert sp3.rejected["line"].to_list() == list(range(95, 101))
    assert any("epoch lines rejected" in n and "'duplicate_epoch': 1" in n for n in report.notes)
    whole, _ = read_sp3(IGS)
    t = [_as_time(dt.datetime(2019, 1, 14) + dt.timedelta(minutes=15 * k)) for k in range(12) if k != 10]
    assert sp3.time.tolist() == t  # 02:30 is missing, not 00:30
    assert np.array_equal(sp3.position, whole.position[[k for k in range(12) if k != 10]], equal_nan=True)
    with pytest.raises(InputError, match=r"sp3-hour-changed\.sp3:94: epoch line repeating the time"):
        read_sp3(path, strict=True)


@pytest.mark.parametrize(
    ("k", "new", "reason", "dropped"),
    [
        (10, "*  2019  1 14  0 31  0.00000000", "epoch_out_of_order", 10),  # back, to a new time
        (2, "*  2019  1 14  2 50  0.00000000", "epoch_out_of_order", 2),  # forward: the later epochs stay
        (3, "*  2019  1 14  0 30  0.00000000", "duplicate_epoch", 3),  # repeated just after
    ],
    ids=["back", "forward", "repeat"],
)
def test_epoch_order_keeps_the_longest_increasing_run(tmp_path, k, new, reason, dropped):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    lines[stars[k]] = new
    sp3, report = read_sp3(_write(tmp_path, "order.sp3", lines))
    whole, _ = read_sp3(IGS)
    assert report.rejected == {reason: 6} and report.unaccounted == 0
    assert report.first_bad.endswith(f":{stars[k] + 1}: {reason}")
    assert sp3.time.tolist() == np.delete(whole.time, dropped).tolist()


@pytest.mark.parametrize("year", ["1979", "0000", "9999", "2200", str(PLAUSIBLE_END.year)])
def test_epoch_years_outside_the_gnss_era_are_rejected(tmp_path, year):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    lines[stars[5]] = lines[stars[5]][:3] + year + lines[stars[5]][7:]
    sp3, report = read_sp3(_write(tmp_path, "year.sp3", lines))
    assert report.rejected == {"time_out_of_range": 6} and report.unaccounted == 0
    assert len(sp3.time) == 95 and report.first_bad.endswith(f":{stars[5] + 1}: time_out_of_range")
    with pytest.raises(InputError, match=r"epoch outside 1980-01-06 to"):
        read_sp3(_write(tmp_path, "year.sp3", lines), strict=True)


def test_a_non_finite_position_is_counted_as_invalidated():
    path = BAD / "sp3-inf-position.sp3"
    sp3, report = read_sp3(path)
    assert (report.rows_read, report.rows_kept, report.rejected) == (72, 72, {})
    assert report.invalidated == {"missing_clock": 3, "non_finite_position": 1}
    assert report.first_bad == f"{path}:54: non_finite_position"
    i, j = 4, sp3.sat_index(["G07"])[0]  # 01:00, G07
    assert np.isnan(sp3.position[i, j]).all() and np.isfinite(sp3.clock[i, j])
    assert np.isfinite(np.delete(sp3.position.reshape(-1, 3), i * 6 + j, axis=0)).all()


def test_non_finite_and_unreadable_values(tmp_path):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    p = [stars[k] + 2 for k in range(1, 6)]  # G07 of epochs 1-5
    lines[p[0]] = lines[p[0]][:46] + "NaN".rjust(14) + lines[p[0]][60:]  # clock
    lines[p[1]] = lines[p[1]][:18] + "-1e300".rjust(14) + lines[p[1]][32:]  # y: 1e303 m
    lines[p[2]] = lines[p[2]][:46] + "  52.1OOOOO" + lines[p[2]][57:]  # unreadable clock
    lines[p[3]] = lines[p[3]][:32] + "1e308".rjust(14) + lines[p[3]][46:]  # z overflows to inf
    lines[p[4]] = lines[p[4]][:4] + "  1234.5678\x0090" + lines[p[4]][18:]  # a NUL byte in x
    sp3, report = read_sp3(_write(tmp_path, "values.sp3", lines))
    assert report.rejected == {"bad_record": 1} and report.unaccounted == 0
    assert report.invalidated == {
        "bad_clock": 1,
        "implausible_position": 1,
        "missing_clock": 40,
        "non_finite_clock": 1,
        "non_finite_position": 1,
    }
    j = sp3.sat_index(["G07"])[0]
    assert np.isnan(sp3.clock[[1, 3], j]).all() and np.isnan(sp3.position[[2, 4, 5], j]).all()


def test_every_line_is_kept_or_rejected_once(tmp_path):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    lines[stars[3] + 1] = "PG31" + lines[stars[3] + 1][4:]  # unlisted, in an epoch later rejected
    lines[stars[3]] = "*  2019  1 14 25 45  0.00000000"  # hour 25: unreadable
    lines.insert(stars[0], "PG07  1.0 2.0 3.0")  # before the first epoch
    lines.insert(stars[8] + 3, "XG07 garbage")  # a line of no SP3 record type
    lines.insert(stars[8] + 3, lines[stars[8] + 2])  # a satellite repeated in its epoch
    sp3, report = read_sp3(_write(tmp_path, "lines.sp3", lines))
    assert report.rejected == {"bad_epoch": 6, "no_epoch": 1, "duplicate": 1, "unknown_line": 1}
    assert report.rows_read == 576 + 3 and report.rows_kept == 570 and report.unaccounted == 0
    assert sp3.rejected.height == report.n_rejected and len(sp3.time) == 95
    assert report.first_bad.endswith(f":{stars[0] + 1}: no_epoch")


def test_overlapping_files_keep_the_first_and_count_the_rest(tmp_path):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    head = lines[: stars[0]]
    first = _write(tmp_path, "a.sp3", head + lines[stars[0] : stars[50]] + ["EOF"])
    later = lines[stars[48] :]
    later[1] = later[1][:4] + f"{1.0:14.6f}" + later[1][18:]  # 12:00 G04 differs in the second file
    second = _write(tmp_path, "b.sp3", head + later)
    whole, _ = read_sp3(IGS)
    merged, report = read_sp3([first, second])
    assert np.array_equal(merged.position, whole.position, equal_nan=True)  # the first file's 12:00
    assert report.rejected == {"epoch_in_earlier_file": 12} and report.unaccounted == 0
    assert (report.rows_read, report.rows_kept) == (576 + 12, 576)
    assert report.invalidated == read_sp3(IGS)[1].invalidated  # the dropped lines are not counted twice
    assert set(merged.rejected["file"]) == {str(second)}
    assert merged.rejected["line"].to_list() == [len(head) + 2 + k for k in (*range(6), *range(7, 13))]
    read_sp3([first, second], strict=True)  # the documented rule, not an error


def test_velocities_of_one_file_survive_the_merge(tmp_path):
    lines = _lines(IGS)
    stars = _epoch_lines(lines)
    head = lines[: stars[0]]
    part = lines[stars[0] : stars[48]]
    part.insert(2, "VG04  12345.678901 -23456.789012   3456.789012      0.123456")
    a = _write(tmp_path, "a.sp3", head + part)
    b = _write(tmp_path, "b.sp3", head + lines[stars[48] :])
    merged, report = read_sp3([b, a])
    assert merged.velocity is not None and merged.velocity[0, 0, 0] == 1234.5678901
    assert report.rows_read == 577 == report.rows_kept


def test_too_few_epochs_to_interpolate_names_the_file(tmp_path):
    lines = _lines(IGS)
    path = _write(tmp_path, "short.sp3", lines[: _epoch_lines(lines)[5]])
    sp3, report = read_sp3(path)
    assert len(sp3.time) == 5 and report.unaccounted == 0
    with pytest.raises(InputError, match=r"short\.sp3: 5 SP3 epochs, too few .* degree 10 needs 11"):
        interpolate_position(sp3, "G07", sp3.time[2])
    one = dataclasses.replace(sp3, time=sp3.time[:1], clock=sp3.clock[:1])
    assert np.isnan(interpolate_clock(one, "G07", sp3.time[0]))
