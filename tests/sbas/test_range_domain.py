"""Range-domain errors (issue 6 item 6, GIMAT 3.4) on the synthetic Toulouse fixture.

The synthetic observations were generated from the IGS SP3 orbits and clocks of the day
(shared/data/egnos-ems-prn123-2019-014/synthetic-obs/README.md): C1 = SP3 range at transmission
- c (SP3 clock + relativistic term) + c TGD - c DCB(P1-C1) + T_synth + I_GIM, no noise, receiver
clock 0. So against SP3 only model differences remain: the EGNOS grid against the IGS map
ionosphere, MOPS against the generator's troposphere, DCB (below 0.8 m) and the EGNOS-corrected
orbit and clock errors; all are well below the SBAS sigmas, which also carry sigma_air (>= 0.39 m)
for noise and multipath these files do not have.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.ems import read_ems
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.sp3 import read_sp3
from overbound.sbas.engine import run_sbas
from overbound.sbas.messages import decode
from overbound.sbas.range_domain import RANGE_COLUMNS, range_errors
from overbound.stats.krs import krs_test

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"


@functools.cache
def _case():
    obs, _ = read_rinex_obs(FIX / "SYNT0140_h02-04.19o.gz")
    frames, _ = read_ems([DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"])
    nav, _ = read_rinex_nav(FIX / "brdc0140.19n.gz")
    sp3, _ = read_sp3(DATA / "range_domain" / "igs20361_h00-07.sp3.gz")
    rx = obs.header.approx_position
    res = run_sbas(obs.table, nav.table, decode(frames), rx)
    return res, nav, sp3, rx, range_errors(res.satellites, sp3, nav.table, rx)


def test_table_and_consistency():
    res, _, _, _, rd = _case()
    assert rd.columns == list(RANGE_COLUMNS)
    assert rd.height == res.satellites["used"].sum() > 3000  # the SP3 data cover every used satellite
    j = rd.join(res.satellites.select("time", "prn", "prefit"), on=("time", "prn"))
    # SP3 terms cancel in the total: the engine's pre-fit residual less the receiver clock estimate
    np.testing.assert_allclose(j["error"], j["prefit"] - j["clock"], atol=1e-9)
    np.testing.assert_allclose(rd["error"], rd["measurement"] - rd["sis"], atol=1e-9)
    np.testing.assert_allclose(rd["normalised"], rd["error"] / rd["sigma"])
    # the clock estimate is the weighted least-squares one: weighted residuals sum to 0 per epoch
    wsum = rd.group_by("time").agg((pl.col("error") / pl.col("sigma") ** 2).sum())["error"]
    assert wsum.abs().max() < 1e-9


def test_sp3_truth_recovers_the_synthetic_ionosphere():
    # PR - (SP3 satellite term) - T_synth is I_GIM - c DCB by construction: a wrong transmission time,
    # clock sign or rotation would leave metres to kilometres; it must track the SBAS ionosphere
    res, _, _, _, rd = _case()
    j = rd.join(res.satellites.select("time", "prn", "iono", "tropo"), on=("time", "prn"))
    e = np.deg2rad(j["elevation"].to_numpy())
    t_synth = 2.3 * np.exp(-0.116e-3 * 207.0) * 1.001 / np.sqrt(0.002001 + np.sin(e) ** 2)
    iono_truth = (j["measurement"] + j["clock"] + j["iono"] + j["tropo"]).to_numpy() - t_synth
    assert np.abs(iono_truth).max() < 8.0  # slant ionosphere at night plus DCB
    assert np.corrcoef(iono_truth, j["iono"])[0, 1] > 0.6
    assert np.abs(rd["sis"]).max() < 3.0  # EGNOS-corrected orbit and clock against IGS finals


def test_normalised_errors_are_well_bounded():
    rd = _case()[-1]
    for col in ("normalised", "sis_normalised", "measurement_normalised"):
        x = rd[col].to_numpy()
        assert np.all(np.isfinite(x))
        assert np.abs(x).max() < 3.0 and x.std() < 0.75, col
        assert krs_test(x, l_min=0.5, l_tail=3.0).overbounded, col
    assert rd["normalised"].std() < 0.5  # noise-free data against sigmas that include sigma_air


def test_bad_input():
    res, nav, sp3, rx, _ = _case()
    with pytest.raises(ValueError, match="lacks"):
        range_errors(res.satellites.drop("iono"), sp3, nav.table, rx)
    with pytest.raises(ValueError, match="TGD"):
        prn = res.satellites.filter(pl.col("used"))["prn"][0]
        range_errors(res.satellites, sp3, nav.table.filter(pl.col("prn") != prn), rx)
