"""Counting KPIs against gLAB's own SBAS summary of the same processing (independent implementation).

gLAB v6.0.0 processed the EGNOS day of 2019-01-14 (synthetic noise-free observations at a known
Toulouse point, real EGNOS PRN 123 messages) and printed both its per-epoch output, which overbound
reads, and its summary, whose numbers are the reference here. ``tests/reference/run_glab_fullday.sh``
makes both files; ``tests/data/glab/PROVENANCE.md`` says how gLAB was obtained.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from overbound.io import read
from overbound.methods.counting import continuity_risk, count_kpis
from overbound.services import SERVICES

DATA = Path(__file__).parents[1] / "data" / "glab"
SUMMARY = (DATA / "synt0140_egnos123_v6_fullday.summary.txt").read_text()


def _glab(label: str) -> str:
    """The text after ``label`` on gLAB's summary line that holds it."""
    line = next(ln for ln in SUMMARY.splitlines() if label in ln)
    return line.split(label, 1)[1].strip()


def _number(label: str) -> float:
    return float(re.match(r"[-+0-9.E]+", _glab(label)).group(0))


@pytest.fixture(scope="module")
def glab_day():
    table, _ = read(DATA / "synt0140_egnos123_v6_fullday.glab.gz")
    return table, count_kpis(table, [SERVICES["APV-I"]])


def test_alert_limits_of_the_glab_summary_are_apv1():
    assert _number("Horizontal Alarm limit:") == SERVICES["APV-I"].hal
    assert _number("Vertical   Alarm limit:") == SERVICES["APV-I"].val


def test_epoch_counts(glab_day):
    _, c = glab_day
    assert c.n_total == _number("Total epochs processed:") == 2820
    assert c.n_with_solution == _number("Total epochs processed with PA solution:")


def test_availability_under_alert_limits(glab_day):
    _, c = glab_day
    k = c.services["APV-I"].combined
    assert k.n_available == _number("Total epochs processed with PA solution under alarm limits:")
    pct = float(re.search(r"\(\s*([0-9.]+)%", _glab("under alarm limits:")).group(1))
    assert 100 * k.availability == pytest.approx(pct, abs=5e-4)


def test_no_misleading_information(glab_day):
    _, c = glab_day
    k = c.services["APV-I"]
    assert (
        _number("Total epochs with Horizontal MIs:")
        == k.horizontal.stanford.mi + k.horizontal.stanford.hmi
        == 0
    )
    assert (
        _number("Total epochs with Vertical   MIs:") == k.vertical.stanford.mi + k.vertical.stanford.hmi == 0
    )


@pytest.mark.parametrize(
    ("axis", "label"),
    [("horizontal", "Worst Horizontal Integrity Ratio:"), ("vertical", "Worst Vertical   Integrity Ratio:")],
)
def test_worst_integrity_ratio_is_the_safety_index_maximum(glab_day, axis, label):
    _, c = glab_day
    assert c.safety[axis].max == pytest.approx(_number(label), abs=5e-5)  # gLAB prints 4 decimals


@pytest.mark.parametrize(
    ("attr", "label"),
    [
        ("hpe95", "Horizontal  95 Positioning Error Percentile:"),
        ("vpe95", "Vertical    95 Positioning Error Percentile:"),
    ],
)
def test_95th_percentile_errors(glab_day, attr, label):
    _, c = glab_day
    # gLAB prints 2 decimals and takes an order statistic; overbound interpolates (type 7)
    assert getattr(c, attr) == pytest.approx(_number(label), abs=0.006)


def test_maximum_protection_levels(glab_day):
    """gLAB's summary rounds to 2 decimals what SBASOUT prints with 4 (89.1750 -> 89.18)."""
    table, _ = glab_day
    assert np.nanmax(table["hpl"].to_numpy()) == pytest.approx(
        _number("Maximum Horizontal Protection  Level:"), abs=0.0051
    )
    assert np.nanmax(table["vpl"].to_numpy()) == pytest.approx(
        _number("Maximum Vertical   Protection  Level:"), abs=0.0051
    )


def test_continuity_window_counting_matches_glab_epoch_window(glab_day):
    """gLAB's airborne continuity slides a window of 15 *epochs*; at 30 s that is 450 s of time.

    overbound measures windows in time (15 s for approaches, not countable at 30 s sampling); with a
    450 s window the same data give gLAB's count exactly.
    """
    table, c = glab_day
    m = re.search(
        r"([0-9.E+-]+) \(NumEpochsRisk:\s*(\d+) TotalEpochsAvailable:\s*(\d+)\)",
        _glab("Continuity Risk Airborne (15 epochs sliding window):"),
    )
    risk, n_fail, n_windows = float(m.group(1)), int(m.group(2)), int(m.group(3))
    available = ((table["hpl"] < 40) & (table["vpl"] < 50)).fill_null(False).to_numpy()
    res = continuity_risk(table["time"].dt.epoch("us").to_numpy(), available, window_s=15 * 30)
    assert (res.n_fail, res.n_windows) == (n_fail, n_windows)
    assert res.risk == pytest.approx(risk, rel=1e-4)
    assert c.services["APV-I"].combined.continuity.risk is None  # 15 s windows at 30 s sampling
