"""report.html in a real browser: headless Debian Chromium through Selenium, offline.

Skips when Chromium, ChromeDriver or Selenium is missing, unless ``OVERBOUND_REQUIRE_BROWSER=1``
(CI), in which case it fails. The driver is the system one (``/usr/bin/chromedriver``), so
Selenium Manager downloads nothing, and Chromium's background networking is off.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.report.html import section_ids, write_report

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)
WIDTH = 1280

pytestmark = pytest.mark.browser


def _unavailable(reason: str) -> None:
    if os.environ.get("OVERBOUND_REQUIRE_BROWSER") == "1":
        pytest.fail(f"OVERBOUND_REQUIRE_BROWSER=1 but {reason}")
    pytest.skip(reason)


@pytest.fixture
def driver(tmp_path):
    missing = [str(p) for p in (CHROMIUM, CHROMEDRIVER) if not p.exists()]
    if missing:
        _unavailable(f"{' and '.join(missing)} not installed (apt-get install chromium chromium-driver)")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _unavailable("selenium is not installed (pip install -e '.[test]')")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path / 'chromium-profile'}")
    options.add_argument(f"--window-size={WIDTH},1000")
    browser = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
    try:
        yield browser
    finally:
        browser.quit()


def _table() -> pl.DataFrame:
    """A day at 1 Hz with a VPL excursion above 35 m and a gap, so every figure has something to show."""
    rng = np.random.default_rng(11)
    n = 86_400
    k = np.arange(n)
    time = np.datetime64("2006-12-27T00:00:00", "us") + (k * 1_000_000).astype("timedelta64[us]")
    vpl = 20 + 6 * np.abs(np.sin(k / 7000)) + rng.gamma(2.0, 1.0, n)
    vpl[30_000:30_300] = 42.0
    table = pl.DataFrame(
        {
            "time": time,
            "station": "USLO",
            "hpe": np.hypot(rng.normal(0, 0.8, n), rng.normal(0, 0.8, n)),
            "vpe": rng.normal(0, 1.2, n),
            "hpl": 12 + 4 * np.abs(np.sin(k / 5000)) + rng.gamma(2.0, 1.0, n),
            "vpl": vpl,
        }
    )
    return table.filter((pl.int_range(pl.len()) < 60_000) | (pl.int_range(pl.len()) >= 63_600))


def test_report_renders_in_chromium(driver, tmp_path):
    from selenium.webdriver.common.by import By

    analysis = analyze(
        _table(), services=["NPA", "LPV", "LPV-200", "CAT-I"], title="USLO 2006-361 (synthetic)"
    )
    path = write_report(analysis, tmp_path)
    driver.get(path.resolve().as_uri())
    assert driver.execute_script("return document.readyState") == "complete"

    assert driver.title == "USLO 2006-361 (synthetic) — overbound integrity report"
    for sid in section_ids(analysis):
        section = driver.find_element(By.ID, sid)
        assert section.is_displayed(), sid
        assert section.find_element(By.TAG_NAME, "h2").is_displayed(), sid

    images = driver.execute_script(
        "return Array.from(document.images).map(i => "
        "[i.dataset.figure, i.complete, i.naturalWidth, i.naturalHeight, i.getBoundingClientRect().width])"
    )
    assert len(images) == 1 + 2 + 2 + 2 + 4
    for name, complete, width, height, shown in images:
        assert complete and width > 0 and height > 0, name
        assert 0 < shown <= WIDTH, name  # scaled to the page, never wider than the window
    # the page loaded nothing but itself
    assert driver.execute_script("return performance.getEntriesByType('resource').length") == 0
    # two Stanford diagrams side by side: same row, different columns
    rects = driver.execute_script(
        "return ['horizontal', 'vertical'].map(a => document.querySelector("
        "`img[data-figure='stanford-LPV-200-${a}']`).getBoundingClientRect().toJSON())"
    )
    assert rects[0]["top"] == rects[1]["top"] and rects[0]["right"] <= rects[1]["left"]
    badges = [b.text for b in driver.find_elements(By.CSS_SELECTOR, "#service-LPV-200 .badge")]
    assert badges == [
        "within",
        "outside",
        "within",
        "within",
    ]  # the VPL excursion breaks continuity; no HMI badge

    height = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(WIDTH, min(height + 120, 16_000))
    shot = tmp_path / "report.png"
    assert driver.save_screenshot(str(shot))
    assert shot.stat().st_size > 50_000


def test_verdicts_first_and_nothing_overflows_at_1024(driver, tmp_path):
    """The report opens with the verdict matrix; no table or figure is wider than a 1024 px window."""
    from selenium.webdriver.common.by import By

    from overbound.simulate import SimulationConfig, simulate

    sim = simulate(SimulationConfig(days=1, seed=3, anomalies=("band:15:16:3",)))
    analysis = analyze(
        sim.table,
        services=["NPA", "APV-I", "LPV", "LPV-200"],
        confidence=None,
        evt=None,
        parametric=True,
        evt_n_boot=50,
        title="Simulated day with a PL-band anomaly",
    )
    path = write_report(analysis, tmp_path)
    driver.set_window_size(1024, 900)
    driver.get(path.resolve().as_uri())
    first = driver.execute_script("return document.querySelector('main section').id")
    assert first == "verdicts"
    rows = driver.find_elements(By.CSS_SELECTOR, "#verdicts table.verdicts tbody tr")
    assert [r.get_attribute("data-service") for r in rows] == ["NPA", "APV-I", "LPV", "LPV-200"]
    cells = driver.find_elements(By.CSS_SELECTOR, "#verdicts table.verdicts td")
    assert len(cells) == 4 * 6
    assert {c.get_attribute("data-verdict") for c in cells} <= {"pass", "fail", "not demonstrated"}
    # the matrix is on the first screen, above every other section
    top = driver.execute_script("return document.getElementById('verdicts').getBoundingClientRect().top")
    assert 0 < top < 400
    # every cell links to an evidence block that exists
    for c in cells:
        href = c.find_element(By.TAG_NAME, "a").get_attribute("href").split("#")[1]
        assert driver.find_elements(By.ID, href), href
    width = driver.execute_script("return document.documentElement.clientWidth")
    assert driver.execute_script("return document.documentElement.scrollWidth") <= width
    wide = driver.execute_script(
        "const W = document.documentElement.clientWidth; return Array.from("
        "document.querySelectorAll('main table, main figure, main img')).filter("
        "e => e.getBoundingClientRect().right > W + 0.5)"
        ".map(e => e.tagName + ' ' + (e.closest('section')||{}).id)"
    )
    assert wide == []
    # the smallest annotation (6.5 pt at FIGURE_DPI) stays at least 8 px on screen in every figure
    from overbound.report.page import FIGURE_DPI

    scales = driver.execute_script(
        "return Array.from(document.images).map(i => "
        "[i.dataset.figure, i.getBoundingClientRect().width / i.naturalWidth])"
    )
    px = 6.5 * FIGURE_DPI / 72
    small = [(name, round(px * k, 1)) for name, k in scales if px * k < 8]
    assert small == []
    # the sticky navigation stays on screen while scrolling
    driver.execute_script("window.scrollTo(0, document.body.scrollHeight / 2)")
    nav_top = driver.execute_script("return document.querySelector('nav.sticky').getBoundingClientRect().top")
    assert nav_top == 0
    # no probability below 1e-15 printed as a number anywhere in the page
    text = driver.find_element(By.TAG_NAME, "main").text
    import re

    tiny = [m for m in re.findall(r"\d(?:\.\d+)?e-(\d+)", text) if int(m) > 15]
    assert tiny == []
    tiny_html = re.findall(r"10\n?−(\d+)", text)
    assert all(int(x) <= 15 for x in tiny_html), tiny_html


def test_service_map_renders_in_chromium(driver, tmp_path):
    """``overbound sbas-map``'s page: every map drawn, nothing loaded, nothing wider than 1024 px."""
    from click.testing import CliRunner
    from selenium.webdriver.common.by import By

    from overbound.cli import main

    engine = Path(__file__).resolve().parents[1] / "data" / "sbas" / "engine"
    files = ["--nav", str(engine / "brdc0140.19n.gz"), "--sbas", str(engine / "ems_1930-2210.ems.gz")]
    grid = ["--area", "-10", "30", "35", "65", "--step", "10", "--interval", "1"]
    span = ["--start", "2019-01-14T20:00:00", "--end", "2019-01-14T20:20:00"]
    args = [
        "sbas-map",
        *files,
        *grid,
        *span,
        "--service",
        "LPV",
        "--service",
        "LPV-200",
        "-o",
        str(tmp_path / "map"),
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    driver.set_window_size(1024, 900)
    driver.get((tmp_path / "map" / "map.html").resolve().as_uri())
    assert driver.title == "SBAS service-volume map — overbound"
    for sid in ("service-LPV", "service-LPV-200", "common"):
        assert driver.find_element(By.ID, sid).is_displayed(), sid
    images = driver.execute_script(
        "return Array.from(document.images).map(i => [i.dataset.figure, i.complete, i.naturalWidth])"
    )
    names = sorted(n for n, _, _ in images)
    maps = [f"{kind}-{s}" for kind in ("availability", "continuity") for s in ("LPV", "LPV-200")]
    assert names == sorted([*maps, "iono_availability", "hpl_p95", "vpl_p95"])
    assert all(complete and width > 0 for _, complete, width in images)
    assert driver.execute_script("return performance.getEntriesByType('resource').length") == 0
    width = driver.execute_script("return document.documentElement.clientWidth")
    assert driver.execute_script("return document.documentElement.scrollWidth") <= width
