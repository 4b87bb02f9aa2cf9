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
