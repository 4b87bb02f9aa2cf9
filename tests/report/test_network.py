"""The network part of a campaign report: heat map, station map, daily compliance, sorting."""

from __future__ import annotations

import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.io.dataset import read_manifest, write_manifest
from overbound.report.html import section_ids, write_report
from overbound.report.json import summary_dict
from overbound.report.network import land_rings, plot_availability_heatmap, plot_station_map
from overbound.simulate import SimulationConfig, write_simulation_dataset

sys.path.insert(0, str(Path(__file__).parent))
from test_browser import driver  # noqa: F401  (the headless Chromium fixture)

POSITIONS = {"SIM01": (43.56, 1.48), "SIM02": (50.8, 4.35), "SIM03": (40.4, -3.7)}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """3 stations x 3 days at 10 s, with positions in the manifest; counting only."""
    root = tmp_path_factory.mktemp("net") / "ds"
    write_simulation_dataset(SimulationConfig(days=3, interval_s=10.0, stations=3, seed=8), root)
    manifest = read_manifest(root)
    for name, (lat, lon) in POSITIONS.items():
        manifest["stations"][name]["reference"] = [lat, lon, 100.0]
    write_manifest(root, manifest)
    return analyze([root], counting_only=True)


def test_heatmap_shows_one_minus_availability_per_station_day() -> None:
    daily = pl.DataFrame(
        {
            "station": ["A", "A", "B"],
            "date": [dt.date(2024, 1, 7), dt.date(2024, 1, 9), dt.date(2024, 1, 8)],
            "n_epochs": [10, 10, 10],
            "LPV": [0.99, 1.0, 0.5],
        }
    )
    ax = plot_availability_heatmap(daily, "LPV")
    (im,) = [a for a in ax.get_images() if a.get_gid() == "heatmap"]
    grid = np.ma.filled(im.get_array(), np.nan)
    assert grid.shape == (2, 3)
    np.testing.assert_allclose(grid[0, [0, 2]], [0.01, 1e-5])  # full availability drawn at the floor
    np.testing.assert_allclose(grid[1, 1], 0.5)
    assert np.isnan(grid[0, 1]) and np.isnan(grid[1, 0]) and np.isnan(grid[1, 2])  # no data: blank


def test_station_map_places_and_colours_the_stations() -> None:
    rings = land_rings()
    assert len(rings) > 200
    lon, lat = np.concatenate(rings).T
    assert lon.min() >= -180 and lon.max() <= 180 and lat.min() >= -90 and lat.max() <= 90
    ax = plot_station_map(POSITIONS, {"SIM01": 0.999, "SIM02": 0.9, "SIM03": 1.0}, "LPV")
    (sc,) = [c for c in ax.collections if c.get_gid() == "stations"]
    np.testing.assert_allclose(sc.get_offsets(), [(lon, lat) for lat, lon in POSITIONS.values()])
    np.testing.assert_allclose(sc.get_array(), [1e-3, 0.1, 1e-5], rtol=1e-9)


def test_network_section_and_summary(campaign, tmp_path: Path) -> None:
    doc = summary_dict(campaign)
    net = doc["network"]
    assert net["partitions"] == net["partitions_analysed"] == 9
    lpv = net["daily_compliance"]["LPV"]
    days = net["days"]
    expected = [d["availability"]["LPV"] >= 0.99 for st in days.values() for d in st]
    assert lpv["network"] == pytest.approx(np.mean(expected))
    assert doc["verdicts"] == {}  # counting only: nothing assessed
    json.dumps(doc)
    html = write_report(campaign, tmp_path, summary=doc).read_text()
    assert "network" in section_ids(campaign)
    for name in ("heatmap-LPV", "heatmap-NPA", "station-map"):
        assert f'data-figure="{name}"' in html
    assert "Not assessed" in html and 'class="sortable"' in html


def test_station_table_sorts_in_the_browser(campaign, tmp_path: Path, driver) -> None:  # noqa: F811
    path = write_report(campaign, tmp_path)
    driver.get(path.as_uri())
    table = driver.find_element("css selector", "#stations table.sortable")
    head = table.find_elements("css selector", "thead th")[7]  # availability H+V

    def column() -> list[float]:
        cells = [
            r.find_elements("css selector", "td")[7].text
            for r in table.find_elements("css selector", "tbody tr")
        ]
        return [float(c.rstrip(" %").replace("\u00a0", "")) for c in cells]

    before = column()
    driver.execute_script("arguments[0].click()", head)
    assert column() == sorted(before)
    driver.execute_script("arguments[0].click()", head)
    assert column() == sorted(before, reverse=True)
