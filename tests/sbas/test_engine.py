"""DO-229 user engine against gLAB v6 on the same files, plus unit checks of its pieces.

Fixture (tests/data/sbas/engine, PROVENANCE.md there): synthetic noise-free Toulouse observations
02:00-05:00 GPST of 2019-01-14, the day's broadcast ephemerides, the real EGNOS PRN 123 EMS hours
02-04, and gLAB's SBAS PA processing of exactly these files (SBASOUT, SBASVAR, SBASUNSEL lines).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.ems import read_ems
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.schema import REQUIRED
from overbound.sbas import iono, tropo
from overbound.sbas.engine import REASONS, SbasOptions, run_sbas
from overbound.sbas.messages import decode
from overbound.sbas.solution import weighted_least_squares

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"


@pytest.fixture(scope="module")
def run():
    obs, _ = read_rinex_obs(FIX / "SYNT0140_h02-04.19o.gz")
    nav, _ = read_rinex_nav(FIX / "brdc0140.19n.gz")
    frames, _ = read_ems([DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"])
    return run_sbas(obs.table, nav.table, decode(frames), obs.header.approx_position, station="synt")


@pytest.fixture(scope="module")
def glab():
    rows: dict[str, list[list[str]]] = {}
    for line in gzip.decompress((FIX / "glab_h02-04.out.gz").read_bytes()).decode().splitlines():
        parts = line.split()
        rows.setdefault(parts[0], []).append(parts)
    out = pl.DataFrame(
        [(float(r[3]), float(r[15]), float(r[18]), float(r[11]), float(r[12]), float(r[13]),
          " ".join(sorted(s[2:] for s in r[24:] if s.startswith("+")))) for r in rows["SBASOUT"]],
        schema=["sod", "hpl", "vpl", "north", "east", "up", "used"], orient="row",
    )  # fmt: skip
    var = pl.DataFrame(
        [(float(r[3]), int(r[6]), *map(float, r[15:24]), *map(float, r[25:28])) for r in rows["SBASVAR"]
         if r[0] == "SBASVAR"],
        schema=["sod", "prn", "sigma", "sigma_flt", "sigma_udre", "delta_udre", "source", "eps_fc", "eps_rrc",
                "eps_ltc", "eps_er", "sigma_uire", "sigma_tropo", "sigma_air"], orient="row",
    )  # fmt: skip
    return out, var


def _sod(df: pl.DataFrame) -> pl.DataFrame:
    t = pl.col("time")
    sod = t.dt.hour().cast(pl.Int64) * 3600 + t.dt.minute().cast(pl.Int64) * 60 + t.dt.second().cast(pl.Int64)
    return df.with_columns(sod=sod.cast(pl.Float64))


def test_epoch_table_has_the_schema_columns(run):
    assert set(REQUIRED) <= set(run.epochs.columns)
    assert run.epochs["time"].is_sorted()
    assert set(run.satellites["reason"].unique()) <= set(REASONS)


def test_same_epochs_and_satellites_as_glab(run, glab):
    out, _ = glab
    ours = _sod(run.epochs).filter(pl.col("hpl").is_not_nan())
    assert ours["sod"].to_list() == out["sod"].to_list()
    used = (
        _sod(run.satellites).filter("used").sort("sod", "prn")
        .group_by("sod", maintain_order=True)
        .agg(pl.col("prn").cast(pl.String).str.zfill(2).str.join(" "))
    )  # fmt: skip
    j = out.join(used, on="sod", suffix="_ours")
    assert j.height == out.height
    assert (j["used"] == j["prn"]).all()


def test_protection_levels_and_errors_match_glab(run, glab):
    out, _ = glab
    j = _sod(run.epochs).join(out, on="sod", suffix="_glab")
    # gLAB prints 4 decimals; the remaining difference comes from the ionospheric sigma at low elevation
    pairs = (("hpl", "hpl_glab", 0.01), ("vpl", "vpl_glab", 0.01), ("east", "east_glab", 0.02),
             ("north", "north_glab", 0.02), ("vpe", "up", 0.02))  # fmt: skip
    for ours, theirs, tol in pairs:
        worst = float((j[ours] - j[theirs]).abs().max())
        assert worst < tol, (ours, worst)


def test_sigma_terms_match_glab(run, glab):
    _, var = glab
    s = _sod(run.satellites).filter("used").with_columns(pl.col("prn").cast(pl.Int64))
    j = s.join(var, on=("sod", "prn"), suffix="_glab")
    assert j.height == s.height
    for name in ("sigma", "sigma_flt", "eps_fc", "eps_rrc", "eps_ltc", "eps_er", "sigma_uire", "sigma_tropo",
                 "sigma_air", "delta_udre"):  # fmt: skip
        worst = float((j[name] - j[f"{name}_glab"]).abs().max())
        assert worst < 0.005, (name, worst)
    assert float((j["sigma_udre"] - j["sigma_udre_glab"]).abs().max()) < 0.0001


def test_mops_troposphere_values():
    # DO-229D A.4.2.4 by hand at 45 deg N (a table row), day 28 (average minus the full seasonal
    # variation), sea level (d = z): P = 1015.75 + 2.25, T = 283.15 - 11, e = 11.66 - 7.24,
    # beta = 5.58e-3 - 0.32e-3, lambda = 2.57 - 0.46
    d_hyd, d_wet = tropo.zenith_delays(45.0, 0.0, 28)
    z_hyd = 1e-6 * 77.604 * 287.054 * 1018.0 / 9.784
    z_wet = 1e-6 * 382000 * 287.054 / (9.784 * 3.11 - 5.26e-3 * 287.054) * 4.42 / 272.15
    assert d_hyd == pytest.approx(z_hyd, rel=1e-12)
    assert d_wet == pytest.approx(z_wet, rel=1e-12)
    assert tropo.sigma_tropo(np.pi / 2) == pytest.approx(0.12 * 1.001 / np.sqrt(1.002001))


def test_pierce_point_and_obliquity_at_zenith_and_horizon():
    lat, lon = iono.pierce_point(np.array([0.7]), np.array([0.1]), np.array([np.pi / 2]), np.array([0.3]))
    assert lat[0] == pytest.approx(0.7) and lon[0] == pytest.approx(0.1)
    assert iono.obliquity(np.array([np.pi / 2]))[0] == pytest.approx(1.0)
    ratio = iono.R_EARTH / (iono.R_EARTH + iono.H_IONO)
    assert iono.obliquity(np.array([0.0]))[0] == pytest.approx(1 / np.sqrt(1 - ratio**2))


def test_grid_interpolation_reproduces_a_plane():
    # a plane over the IGPs is interpolated exactly, with four points and with any triangle
    rng = np.random.default_rng(1)
    lat = rng.uniform(-55, 55, 200)
    lon = rng.uniform(-180, 175, 200)
    plane = lambda la, lo: 2.0 + 0.03 * la - 0.01 * lo  # noqa: E731
    drop = rng.integers(0, 5, 200)  # 4: keep all four

    def usable(rows, clat, clon):
        u = np.ones(clat.shape, bool)
        k = drop[rows]
        u[np.flatnonzero(k < 4), k[k < 4]] = False
        return u

    ok, clat, clon, w, mode = iono.select_and_interpolate(lat, lon, usable)
    assert ok[drop == 4].all() and ok.sum() > 100 and np.allclose(w.sum(axis=1)[ok], 1.0)
    assert (w[ok] >= -1e-12).all()  # a triangle is used only when it contains the pierce point
    # corners may wrap in longitude; the test points stay away from the date line
    assert np.allclose((w * plane(clat, clon)).sum(axis=1)[ok], plane(lat, lon)[ok])
    assert ((mode[ok] == 0) == (drop[ok] == 4)).all()


def test_wls_recovers_a_known_offset_and_reports_few_satellites():
    elev = np.deg2rad(np.array([80, 45, 30, 20, 60, 15, 70, 25.0]))
    azim = np.deg2rad(np.array([0, 60, 130, 200, 250, 310, 100, 20.0]))
    los = np.stack([np.cos(elev) * np.sin(azim), np.cos(elev) * np.cos(azim), np.sin(elev)], axis=-1)
    truth = np.array([1.0, -2.0, 0.5])
    prefit = -(los @ truth) + 3.0  # y = G x with G = [-los, 1]
    epoch = np.array([0] * 8)
    sol = weighted_least_squares(epoch, 2, elev, azim, prefit, np.ones(8), np.ones(8, bool))
    assert np.allclose(sol.enu[0], truth) and sol.clock[0] == pytest.approx(3.0)
    assert np.isnan(sol.hpl[1]) and sol.nsv[1] == 0
    assert np.allclose(sol.residual, 0.0, atol=1e-9)


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="PA or NPA"):
        SbasOptions(mode="LPV")
