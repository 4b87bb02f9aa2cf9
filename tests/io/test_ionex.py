"""IONEX reader and slant delay (overbound.io.ionex), the CODE DCB reader and the RINEX 2 writer."""

from __future__ import annotations

import datetime as dt
import gzip
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.dcb import read_code_dcb
from overbound.io.ionex import L1_DELAY_PER_TECU, pierce_points, read_ionex, slant_delay_l1, vertical_tec
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.rinex_write import write_rinex2_obs
from overbound.io.schema import InputError

NET = Path(__file__).resolve().parents[1] / "data" / "sbas" / "network"
IONEX = NET / "igsg0140.19i.gz"
US = 1_000_000
MIDNIGHT = int(np.datetime64("2019-01-14T00:00:00", "us").astype(np.int64))
LEAP_US = 18 * US  # IONEX epochs are UT; GPS - UTC = 18 s in 2019


@pytest.fixture(scope="module")
def text() -> list[str]:
    return gzip.decompress(IONEX.read_bytes()).decode().splitlines()


@pytest.fixture(scope="module")
def ionex():
    return read_ionex(IONEX)


def _row_by_hand(lines: list[str], map_no: int, lat: float) -> list[float]:
    """The values of one latitude row of TEC map ``map_no``, read by splitting the text."""
    start = next(
        i for i, s in enumerate(lines) if s[60:].strip() == "START OF TEC MAP" and int(s[:6]) == map_no
    )
    row = next(
        i
        for i in range(start, len(lines))
        if lines[i][60:].startswith("LAT/LON1") and float(lines[i][2:8]) == lat
    )
    values = " ".join(lines[row + 1 : row + 6]).split()
    return [int(v) * 0.1 for v in values]


def test_the_igs_maps_of_the_egnos_day(ionex, text) -> None:
    maps, report = ionex
    assert maps.tec.shape == (13, 71, 73) and maps.rms is not None and maps.rms.shape == maps.tec.shape
    assert maps.lat[0] == 87.5 and maps.lat[-1] == -87.5 and maps.lon[0] == -180 and maps.lon[-1] == 180
    assert maps.height_km == 450 and maps.base_radius_km == 6371 and maps.mapping_function == "COSZ"
    assert maps.time[0] == MIDNIGHT + LEAP_US and np.all(np.diff(maps.time) == 7200 * US)
    for map_no, lat in ((1, 87.5), (1, 42.5), (7, -30.0), (13, 0.0)):
        i = int(np.flatnonzero(maps.lat == lat)[0])
        assert maps.tec[map_no - 1, i] == pytest.approx(_row_by_hand(text, map_no, lat), abs=1e-12)
    assert report.rows_read == report.rows_kept == 13 * 71 * 73 and report.unaccounted == 0
    assert maps.dcb_ns["G01"] == -7.699 and len(maps.dcb_ns) == 32


def test_interpolation_in_space_and_rotated_in_time(ionex) -> None:
    maps, _ = ionex
    t0, t1 = maps.time[3], maps.time[4]
    i, j = int(np.flatnonzero(maps.lat == 45.0)[0]), int(np.flatnonzero(maps.lon == 5.0)[0])
    # a grid node at a map epoch: the node's value
    assert vertical_tec(maps, np.array([t0]), np.array([45.0]), np.array([5.0]))[0] == maps.tec[3, i, j]
    # a cell centre at a map epoch: the mean of its four nodes (eq. 2, p = q = 1/2)
    corners = maps.tec[3, i - 1 : i + 1, j : j + 2]  # latitudes run north to south
    centre = vertical_tec(maps, np.array([t0]), np.array([46.25]), np.array([7.5]))[0]
    assert centre == pytest.approx(corners.mean(), rel=1e-12)
    # halfway between two maps: the mean of both, each read where the Sun has moved it (eq. 3):
    # 3600 s is 15 deg, three grid columns, so the nodes are read exactly
    half = vertical_tec(maps, np.array([(t0 + t1) // 2]), np.array([45.0]), np.array([5.0]))[0]
    assert half == pytest.approx(0.5 * maps.tec[3, i, j + 3] + 0.5 * maps.tec[4, i, j - 3], rel=1e-12)
    # longitudes wrap: 185 deg is -175 deg
    a = vertical_tec(maps, np.array([t0, t0]), np.array([10.0, 10.0]), np.array([185.0, -175.0]))
    assert a[0] == a[1]
    # outside the maps' time span: NaN
    assert np.isnan(vertical_tec(maps, np.array([maps.time[-1] + 1]), np.array([0.0]), np.array([0.0])))[0]


def test_pierce_points_and_slant_factor() -> None:
    lat, lon, slant = pierce_points(
        np.array([45.0, 45.0]), np.array([5.0, 5.0]), np.radians([90.0, 30.0]), np.radians([0.0, 0.0]),
        6371.0, 450.0,
    )  # fmt: skip
    assert lat[0] == pytest.approx(45.0) and lon[0] == pytest.approx(5.0) and slant[0] == pytest.approx(1.0)
    sin_z = 6371.0 / 6821.0 * np.cos(np.radians(30.0))
    assert slant[1] == pytest.approx(1.0 / np.sqrt(1.0 - sin_z**2), rel=1e-12)
    # due north at 30 deg: the pierce point is north by the Earth-centred angle 90 - E - z'
    psi = 90.0 - 30.0 - np.degrees(np.arcsin(sin_z))
    assert lat[1] == pytest.approx(45.0 + psi, rel=1e-12) and lon[1] == pytest.approx(5.0)


def test_slant_delay_is_the_vertical_tec_mapped(ionex) -> None:
    maps, _ = ionex
    t = np.array([maps.time[6]])
    d = slant_delay_l1(maps, t, np.array([45.0]), np.array([5.0]), np.radians([90.0]), np.radians([0.0]))
    i, j = int(np.flatnonzero(maps.lat == 45.0)[0]), int(np.flatnonzero(maps.lon == 5.0)[0])
    assert d[0] == pytest.approx(maps.tec[6, i, j] * L1_DELAY_PER_TECU, rel=1e-12)
    assert L1_DELAY_PER_TECU == pytest.approx(0.1624, abs=1e-4)


def test_bad_maps_are_counted_not_lost(tmp_path: Path, text) -> None:
    lines = list(text)
    starts = [i for i, s in enumerate(lines) if s[60:].strip() == "START OF TEC MAP"]
    lines[starts[1] + 3] = "  12   12   1x" + lines[starts[1] + 3][14:]  # map 2: an unreadable value
    lines[starts[2] + 3] = "9999".rjust(5) + lines[starts[2] + 3][5:]  # map 3: one value missing
    epoch = starts[4] + 1
    lines[epoch] = lines[starts[3] + 1]  # map 5 repeats the epoch of map 4
    path = tmp_path / "bad.19i"
    path.write_text("\n".join(lines) + "\n")
    maps, report = read_ionex(path)
    grid = 71 * 73
    assert report.rejected == {"bad_row": grid, "duplicate_map": grid}
    assert report.invalidated == {"no_value": 1}
    assert report.rows_read == 13 * grid and report.unaccounted == 0
    assert report.first_bad == f"{path}:{starts[1] + 1}: bad_row"
    assert len(maps.time) == 11 and np.isnan(maps.tec[1, 0, 0])


def test_not_an_ionex_file(tmp_path: Path) -> None:
    path = tmp_path / "x.19i"
    path.write_text("hello\n")
    with pytest.raises(InputError, match=r"x\.19i: not an IONEX file"):
        read_ionex(path)


def test_code_dcb() -> None:
    dcb, report = read_code_dcb(NET / "P1C11901.DCB")
    assert dcb.kind == "P1-C1" and dcb.satellites["G01"] == 1.174 and dcb.satellites["G32"] == 1.517
    assert len(dcb.satellites) == 33 and not dcb.receivers  # G01-G32 and G54
    assert report.rows_read == report.rows_kept == 33 and report.unaccounted == 0


def test_rinex2_writer_reads_back(tmp_path: Path) -> None:
    times = [dt.datetime(2019, 1, 14, 0, 0, 30)] * 13 + [dt.datetime(2019, 1, 14, 0, 1, 0, 500000)]
    sats = [f"G{i:02d}" for i in range(1, 14)] + ["G05"]
    c1 = np.linspace(2.0e7, 2.5e7, 14)
    table = pl.DataFrame({"time": times, "sat": sats, "C1": c1, "L1": c1 / 0.19, "S1": np.full(14, 45.25)})
    table = table.with_columns(pl.col("time").cast(pl.Datetime("us")))
    table[3, "L1"] = None  # a missing value is written blank
    where = {"marker": "TEST", "position_ecef": (4627851.2711, 119640.7753, 4372993.8468), "interval_s": 30.0}
    path = write_rinex2_obs(tmp_path / "TEST0140.19o.gz", table, ("C1", "L1", "S1"), **where)
    obs, report = read_rinex_obs(path)
    assert report.n_rejected == 0 and obs.header.marker_name == "TEST"
    assert obs.table.height == 14  # 13 satellites: the epoch line continues on a second line
    assert obs.table["sat"].to_list() == sats
    assert obs.table["time"].to_list() == times
    assert obs.table["C1C"].to_numpy() == pytest.approx(np.round(c1, 3), abs=1e-9)
    assert obs.table["L1C"].is_null().sum() + obs.table["L1C"].is_nan().sum() == 1
    first = path.read_bytes()
    write_rinex2_obs(path, table, ("C1", "L1", "S1"), **where)
    assert path.read_bytes() == first
