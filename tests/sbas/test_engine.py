"""DO-229 user engine against gLAB v6 on the same files, plus unit checks of its pieces.

Fixture (tests/data/sbas/engine, PROVENANCE.md there): synthetic noise-free Toulouse observations
02:00-05:00 GPST of 2019-01-14, the day's broadcast ephemerides, the real EGNOS PRN 123 EMS hours
02-04, and gLAB's SBAS PA processing of exactly these files (SBASOUT, SBASVAR, SBASUNSEL lines).
"""

from __future__ import annotations

import datetime as dt
import functools
import gzip
import io
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest

from overbound.io.ems import read_ems
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.schema import REQUIRED
from overbound.sbas import iono, tropo
from overbound.sbas.corrections import earliest_within, previous_other_value, times_us
from overbound.sbas.engine import (
    IONO_MODE_KLOBUCHAR,
    REASONS,
    SbasOptions,
    _covariance_delta,
    _GridStates,
    _in_regions,
    _service_sets,
    run_sbas,
)
from overbound.sbas.klobuchar import geomagnetic_latitude
from overbound.sbas.messages import AI, DELTA_UDRE, FC_TIMEOUT_PA, decode
from overbound.sbas.solution import weighted_least_squares

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"


#: gLAB comparison cases: observation file, EMS files, gLAB output (PROVENANCE.md).
CASES = {
    "toulouse_02-05": ("SYNT0140_h02-04.19o.gz",
                       (DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"),
                       "glab_h02-04.out.gz"),
    "toulouse_1930-2210": ("SYNT0140_1930-2210.19o.gz", (FIX / "ems_1930-2210.ems.gz",),
                           "glab_synt_1930-2210.out.gz"),
    "brussels_1930-2210": ("SYNB0140_1930-2210.19o.gz", (FIX / "ems_1930-2210.ems.gz",),
                           "glab_synb_1930-2210.out.gz"),
}  # fmt: skip


@functools.cache
def _nav():
    return read_rinex_nav(FIX / "brdc0140.19n.gz")[0]


@functools.cache
def _case(name: str):
    """(name, ours, gLAB tables, (obs, msgs)); the engine uses gLAB's relativistic term so that the
    positions compare at the millimetre."""
    obs_name, ems, glab_name = CASES[name]
    obs, _ = read_rinex_obs(FIX / obs_name)
    frames, _ = read_ems(list(ems))
    msgs = decode(frames)
    opt = SbasOptions(relativity="rv")
    ours = run_sbas(obs.table, _nav().table, msgs, obs.header.approx_position, station="synt", options=opt)
    return name, ours, _read_glab(FIX / glab_name), (obs, msgs)


@pytest.fixture(params=sorted(CASES))
def case(request):
    return _case(request.param)


def _read_glab(path: Path) -> tuple[pl.DataFrame, pl.DataFrame, pl.DataFrame]:
    rows: dict[str, list[list[str]]] = {}
    for line in gzip.decompress(path.read_bytes()).decode().splitlines():
        parts = line.split()
        rows.setdefault(parts[0], []).append(parts)
    out = pl.DataFrame(
        [(float(r[3]), float(r[15]), float(r[18]), float(r[11]), float(r[12]), float(r[13]),
          " ".join(sorted(s[2:] for s in r[24:] if s.startswith("+")))) for r in rows["SBASOUT"]],
        schema=["sod", "hpl", "vpl", "north", "east", "up", "used"], orient="row",
    )  # fmt: skip
    var = pl.DataFrame(
        [(float(r[3]), int(r[6]), *map(float, r[15:24]), *map(float, r[25:28])) for r in rows["SBASVAR"]],
        schema=["sod", "prn", "sigma", "sigma_flt", "sigma_udre", "delta_udre", "source", "eps_fc", "eps_rrc",
                "eps_ltc", "eps_er", "sigma_uire", "sigma_tropo", "sigma_air"], orient="row",
    )  # fmt: skip
    unsel = pl.DataFrame(
        [(float(r[3]), int(r[6]), int(r[9])) for r in rows.get("SBASUNSEL", [])],
        schema=["sod", "prn", "code"], orient="row",
    )  # fmt: skip
    return out, var, unsel


def _sod(df: pl.DataFrame) -> pl.DataFrame:
    t = pl.col("time")
    sod = t.dt.hour().cast(pl.Int64) * 3600 + t.dt.minute().cast(pl.Int64) * 60 + t.dt.second().cast(pl.Int64)
    return df.with_columns(sod=sod.cast(pl.Float64))


def test_epoch_table_has_the_schema_columns(case):
    _, run, _, _ = case
    assert set(REQUIRED) <= set(run.epochs.columns)
    assert run.epochs["time"].is_sorted()
    assert set(run.satellites["reason"].unique()) <= set(REASONS)


def test_same_epochs_and_satellites_as_glab(case):
    _, run, (out, _, _), _ = case
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


def test_protection_levels_and_errors_match_glab(case):
    _, run, (out, _, _), _ = case
    j = _sod(run.epochs).join(out, on="sod", suffix="_glab")
    assert j.height == out.height
    # gLAB prints 4 decimals; what remains is the MOPS tropospheric delay below 6 deg elevation (< 3 mm)
    pairs = (("hpl", "hpl_glab", 0.001), ("vpl", "vpl_glab", 0.001), ("east", "east_glab", 0.005),
             ("north", "north_glab", 0.005), ("vpe", "up", 0.005))  # fmt: skip
    for ours, theirs, tol in pairs:
        worst = float((j[ours] - j[theirs]).abs().max())
        assert worst < tol, (ours, worst)


def test_sigma_terms_match_glab(case):
    _, run, (_, var, _), _ = case
    s = _sod(run.satellites).filter("used").with_columns(pl.col("prn").cast(pl.Int64))
    j = s.join(var, on=("sod", "prn"), suffix="_glab")
    assert j.height == s.height
    for name in ("sigma", "sigma_flt", "eps_fc", "eps_rrc", "eps_ltc", "eps_er", "sigma_uire", "sigma_tropo",
                 "sigma_air", "delta_udre"):  # fmt: skip
        worst = float((j[name] - j[f"{name}_glab"]).abs().max())
        assert worst < 0.005, (name, worst)
    assert float((j["sigma_udre"] - j["sigma_udre_glab"]).abs().max()) < 0.0001


@pytest.mark.parametrize("name", ["toulouse_1930-2210", "brussels_1930-2210"])
def test_evening_window_exercises_iode_change_and_triangle_rule(name):
    _, run, (_, _, unsel), _ = _case(name)
    sats = _sod(run.satellites).with_columns(pl.col("prn").cast(pl.Int64))
    # IODE change-over at 22:03 with no new ephemeris in the daily file: the previous IODE carries on
    prev = sats.filter("used" & pl.col("previous_iode"))
    assert prev.height > 0 and prev["sod"].min() >= 22 * 3600
    # ... until its last correction times out (240 s in PA); then gLAB reports "no broadcast block" (34)
    ours_34 = sats.filter(pl.col("reason") == "no_ephemeris_iode").select("sod", "prn")
    glab_34 = unsel.filter(pl.col("code") == 34).select("sod", "prn")
    assert ours_34.join(glab_34, on=("sod", "prn"), how="anti").height == 0
    assert glab_34.join(ours_34, on=("sod", "prn"), how="anti").height == 0
    # the pierce point outside the triangle of usable IGPs (gLAB 44) rejects the same rows
    ours_44 = sats.filter(pl.col("reason") == "iono_outside_triangle").select("sod", "prn")
    glab_44 = unsel.filter(pl.col("code") == 44).select("sod", "prn")
    assert glab_44.join(ours_44, on=("sod", "prn"), how="anti").height == 0
    if name.startswith("toulouse"):
        assert glab_44.height > 0


def test_default_relativity_differs_from_glab_by_centimetres_only():
    _, run, _, (obs, msgs) = _case("toulouse_02-05")
    kep = run_sbas(obs.table, _nav().table, msgs, obs.header.approx_position)
    both = run.satellites["used"].to_numpy() & kep.satellites["used"].to_numpy()
    d = (kep.satellites["prefit"].to_numpy() - run.satellites["prefit"].to_numpy())[both]
    assert 0.001 < np.abs(d).max() < 0.02


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


def _grid(mask_pts, bad=(), dnu=()):
    """in_mask / status callbacks for a fixed set of IGPs (lat, lon); ``bad`` unusable, ``dnu`` don't use."""

    def member(pts, key):
        clat, clon = iono.igp_position(key)
        wanted = {(round(a), round(b)) for a, b in pts}
        return np.array([[(round(a), round(b)) in wanted for a, b in zip(la, lo, strict=True)]
                         for la, lo in zip(clat, clon, strict=True)]).reshape(clat.shape)  # fmt: skip

    return (lambda rows, key: member(mask_pts, key),
            lambda rows, key: (~member(bad, key), member(dnu, key)))  # fmt: skip


def _full_grid(lat0=30, lat1=60, lon0=-20, lon1=20):
    return [(a, b) for a in range(lat0, lat1 + 1, 5) for b in range(lon0, lon1 + 1, 5)]


def test_grid_interpolation_reproduces_a_plane():
    # a plane over the IGPs is interpolated exactly, with four points and with any triangle
    rng = np.random.default_rng(1)
    lat = rng.uniform(-55, 55, 200)
    lon = rng.uniform(-180, 175, 200)
    plane = lambda la, lo: 2.0 + 0.03 * la - 0.01 * lo  # noqa: E731
    drop = rng.integers(0, 5, 200)  # 4: keep all four

    def status(rows, key):
        u = np.ones(key.shape, bool)
        k = drop[rows]
        u[np.flatnonzero(k < 4), k[k < 4]] = False
        return u, np.zeros(key.shape, bool)

    sel = iono.select_and_interpolate(lat, lon, lambda r, key: np.ones(key.shape, bool), status)
    ok, clat, clon, w, mode = sel.ok, sel.clat, sel.clon, sel.weights, sel.mode
    assert ok[drop == 4].all() and ok.sum() > 100 and np.allclose(w.sum(axis=1)[ok], 1.0)
    assert (w[ok] >= -1e-12).all()  # a triangle is used only when it contains the pierce point
    # corners may wrap in longitude; the test points stay away from the date line
    assert np.allclose((w * plane(clat, clon)).sum(axis=1)[ok], plane(lat, lon)[ok])
    assert ((mode[ok] == 0) == (drop[ok] == 4)).all()
    assert (sel.fail[~ok] == iono.FAIL_OUTSIDE).all()  # one unusable corner and outside: no fall-back


def test_corner_codes_are_the_bits_of_the_corners():
    """Every pattern of four corners (and a non-contiguous view of them) gives its 4-bit number."""
    corners = (np.arange(16)[:, None] >> np.arange(4) & 1).astype(bool)
    np.testing.assert_array_equal(iono._code(corners), np.arange(16))
    wide = np.zeros((16, 8), bool)
    wide[:, ::2] = corners
    np.testing.assert_array_equal(iono._code(wide[:, ::2]), np.arange(16))


def test_grid_selection_follows_do229_a44102():
    lat, lon = np.array([43.0]), np.array([1.0])  # cell 40-45 N, 0-5 E; x = 0.2, y = 0.6
    # all four in the mask, NE corner (45, 5) not monitored: the pierce point is outside the triangle
    # NW-SW-SE (x + y > 1 is false here, so it is inside): three-point interpolation without NE
    s = iono.select_and_interpolate(lat, lon, *_grid(_full_grid(), bad=[(45, 5)]))
    assert s.ok[0] and s.mode[0] == 1 and np.allclose(s.weights[0], [0, 0.6, 0.2, 0.2])
    # SW corner (40, 0) unusable: the pierce point lies outside NE-NW-SE -> no correction, even though
    # a 10x10 cell around it is complete and usable (the cell is chosen from the mask alone)
    s = iono.select_and_interpolate(lat, lon, *_grid(_full_grid(), bad=[(40, 0)]))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_OUTSIDE
    # two unusable corners -> none; a "don't use" corner -> none
    s = iono.select_and_interpolate(lat, lon, *_grid(_full_grid(), bad=[(45, 5), (40, 5)]))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_UNUSABLE
    s = iono.select_and_interpolate(lat, lon, *_grid(_full_grid(), dnu=[(45, 0)]))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_DONT_USE
    # SW corner not in the mask: the triangle NE-NW-SE does not contain the pierce point; the first
    # 10x10 cell (40-50 N, 0-10 E) has that corner too, so the next one, 5 deg west, is taken
    pts = [p for p in _full_grid() if p != (40, 0)]
    s = iono.select_and_interpolate(lat, lon, *_grid(pts))
    assert s.ok[0] and s.mode[0] == 0
    assert np.allclose(s.clat[0], [50, 50, 40, 40]) and np.allclose(s.clon[0], [5, -5, -5, 5])
    assert np.allclose(s.weights[0], [0.18, 0.12, 0.28, 0.42])  # x = 0.6, y = 0.3
    # ... and if that one also lacks a corner, the one 5 deg west and south
    pts = [p for p in _full_grid() if p not in ((40, 0), (50, 5))]
    s = iono.select_and_interpolate(lat, lon, *_grid(pts))
    assert s.ok[0] and s.mode[0] == 0
    assert np.allclose(s.clat[0], [45, 45, 35, 35]) and np.allclose(s.clon[0], [5, -5, -5, 5])
    # three IGPs in the mask whose 5x5 triangle contains the pierce point: a three-point cell, and
    # if one of those three is unusable there is no correction (no fourth corner to fall back on)
    pts = [p for p in _full_grid() if p != (45, 5)]
    s = iono.select_and_interpolate(lat, lon, *_grid(pts))
    assert s.ok[0] and s.mode[0] == 1
    s = iono.select_and_interpolate(lat, lon, *_grid(pts, bad=[(40, 0)]))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_UNUSABLE
    # nothing in the mask
    s = iono.select_and_interpolate(lat, lon, *_grid([]))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_NO_CELL


def test_grid_selection_above_60_degrees_uses_5_by_10_cells():
    # 62 N, 3 E: cell 60-65 N, 0-10 E; IGPs there are 10 deg apart in longitude
    pts = [(a, b) for a in (55, 60, 65, 70) for b in range(-20, 21, 10)]
    s = iono.select_and_interpolate(np.array([62.0]), np.array([3.0]), *_grid(pts))
    assert s.ok[0] and s.mode[0] == 0
    assert np.allclose(s.clat[0], [65, 65, 60, 60]) and np.allclose(s.clon[0], [10, 0, 0, 10])
    assert np.allclose(s.weights[0], [0.3 * 0.4, 0.7 * 0.4, 0.7 * 0.6, 0.3 * 0.6])
    s = iono.select_and_interpolate(np.array([80.0]), np.array([3.0]), *_grid(pts))
    assert not s.ok[0] and s.fail[0] == iono.FAIL_POLAR


def test_previous_other_value_finds_the_last_run_of_another_value():
    key = np.array([1, 1, 1, 1, 2, 1, 2])
    val = np.array([5, 5, 7, 7, 5, 5, 9])
    t = np.array([0, 1, 2, 3, 0, 4, 1])
    prev = previous_other_value(key, val, t, 0)
    # key 1 in time order: 5 5 7 7 5 -> rows 2, 3 point at row 1; row 5 (back to 5) at row 3
    assert prev.tolist() == [-1, -1, 1, 1, -1, 3, 4]


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
    with pytest.raises(ValueError, match="kepler or rv"):
        SbasOptions(relativity="ecef")


# --- NPA mode -----------------------------------------------------------------------------------------
#: gLAB's NPA fall-backs that DO-229D does not have (MOPS-C sigma_flt of 60 m without fast or long-term
#: correction, Klobuchar where the grid fails, any broadcast IODE), as our reasons for not using the row.
GLAB_ONLY_NPA = {"no_iono", "iono_outside_triangle", "no_mt7", "no_long_term", "no_ephemeris_iode",
                 "too_few_satellites"}  # fmt: skip


@functools.cache
def _evening_inputs():
    obs, _ = read_rinex_obs(FIX / "SYNT0140_1930-2210.19o.gz")
    return obs, decode(read_ems([FIX / "ems_1930-2210.ems.gz"])[0])


def _run(msgs, mode: str, klobuchar=None):
    obs, _ = _evening_inputs()
    opt = SbasOptions(mode=mode, relativity="rv")
    ref = obs.header.approx_position
    return run_sbas(obs.table, _nav().table, msgs, ref, options=opt, klobuchar=klobuchar)


def test_npa_matches_glab_npa_where_do229_defines_it():
    _, msgs = _evening_inputs()
    run = _run(msgs, "NPA")
    out, var, _ = _read_glab(FIX / "glab_synt_1930-2210_npa.out.gz")
    sats = _sod(run.satellites).with_columns(pl.col("prn").cast(pl.Int64))
    j = sats.join(
        var.select("sod", "prn", "sigma_flt").with_columns(glab=True), on=("sod", "prn"), how="left"
    )
    assert j.filter("used" & pl.col("glab").is_null()).height == 0  # nothing gLAB does not use
    extra = j.filter(pl.col("glab") & ~pl.col("used"))
    assert set(extra["reason"]) <= GLAB_ONLY_NPA and extra.height < 0.05 * var.height
    # without fast or long-term corrections gLAB's row is its MOPS-C 60 m sigma_flt
    no_corr = extra.filter(pl.col("reason").is_in(["no_mt7", "no_long_term", "no_ephemeris_iode"]))
    assert no_corr.height > 0 and (no_corr["sigma_flt_right"] == 60.0).all()
    both = sats.filter("used").join(var, on=("sod", "prn"), suffix="_glab")
    for name in ("sigma", "sigma_flt", "eps_er", "sigma_uire", "delta_udre"):
        assert float((both[name] - both[f"{name}_glab"]).abs().max()) < 0.005, name
    # epochs with the same satellites: HPL with K_H = 6.18, VPL with K_V = 5.33
    used = both.group_by("sod").len()
    full = (
        var.group_by("sod")
        .len()
        .join(used, on="sod", suffix="_ours")
        .filter(pl.col("len") == pl.col("len_ours"))
    )
    e = _sod(run.epochs).join(out, on="sod", suffix="_glab").join(full, on="sod")
    assert e.height > 0.9 * out.height and (e["mode"] == "NPA").all()
    assert float((e["hpl"] - e["hpl_glab"]).abs().max()) < 0.001
    assert float((e["vpl"] - e["vpl_glab"]).abs().max()) < 0.001


# --- NPA Klobuchar fall-back (DO-229D J.2.3) ---------------------------------------------------------------
def _coefficients():
    return _nav().header.ion_alpha, _nav().header.ion_beta


@functools.cache
def _npa_with_and_without_klobuchar():
    _, msgs = _evening_inputs()
    return _run(msgs, "NPA"), _run(msgs, "NPA", klobuchar=_coefficients())


def _glab_klobuchar_rows() -> pl.DataFrame:
    """(sod, prn) of gLAB's NPA rows on its Klobuchar model (SBASCORR field 51 = 1) and its delay."""
    lines = gzip.decompress((FIX / "glab_synt_1930-2210_npa_klobuchar.out.gz").read_bytes()).decode()
    rows = [r.split() for r in lines.splitlines()]
    return pl.DataFrame([(float(r[3]), int(r[6]), float(r[24])) for r in rows],
                        schema=["sod", "prn", "iono_glab"], orient="row")  # fmt: skip


def test_npa_klobuchar_fallback_uses_exactly_the_rows_glab_does():
    before, after = _npa_with_and_without_klobuchar()
    assert before.counts["klobuchar"] == "no coefficients"
    b, a = (_sod(r.satellites).with_columns(pl.col("prn").cast(pl.Int64)) for r in (before, after))
    gained = a["used"] & ~b["used"]
    new = a.filter(gained)
    assert after.counts["klobuchar"] == new.height > 0 and not (b["used"] & ~a["used"]).any()
    assert (new["iono_mode"] == IONO_MODE_KLOBUCHAR).all()
    assert set(b.filter(gained)["reason"]) == {"no_iono", "iono_outside_triangle"}
    # rows off the broadcast model are untouched (their residuals too, in epochs without a new row)
    off = a["iono_mode"] != IONO_MODE_KLOBUCHAR
    assert a.filter(off).drop("residual").equals(b.filter(off).drop("residual"))
    same_epoch = ~a["sod"].is_in(new["sod"].implode())
    assert a.filter(off & same_epoch).equals(b.filter(off & same_epoch))
    # gLAB's Klobuchar rows: the ones gained, plus those it keeps with its MOPS-C 60 m sigma_flt
    g = _glab_klobuchar_rows()
    assert new.join(g, on=("sod", "prn"), how="anti").height == 0
    rest = g.join(new, on=("sod", "prn"), how="anti").join(a, on=("sod", "prn"))
    assert rest.height == g.height - new.height
    assert set(rest["reason"]) <= {"no_mt7", "no_long_term", "no_ephemeris_iode"}
    # what gLAB's NPA still uses and this engine does not: only its MOPS-C fall-back
    _, var, _ = _read_glab(FIX / "glab_synt_1930-2210_npa.out.gz")
    j = a.join(var.select("sod", "prn").with_columns(glab=True), on=("sod", "prn"), how="left")
    assert j.filter("used" & pl.col("glab").is_null()).height == 0
    extra = j.filter(pl.col("glab") & ~pl.col("used"))
    assert set(extra["reason"]) <= GLAB_ONLY_NPA - {"no_iono", "iono_outside_triangle"}


def test_npa_klobuchar_sigmas_and_levels_against_glab():
    _, after = _npa_with_and_without_klobuchar()
    obs, _ = _evening_inputs()
    lat, lon, _ = pymap3d.ecef2geodetic(*obs.header.approx_position, deg=False)
    out, var, _ = _read_glab(FIX / "glab_synt_1930-2210_npa.out.gz")
    a = _sod(after.satellites).with_columns(pl.col("prn").cast(pl.Int64))
    k = a.filter("used", pl.col("iono_mode") == IONO_MODE_KLOBUCHAR)
    j = k.join(var, on=("sod", "prn"), suffix="_glab").join(_glab_klobuchar_rows(), on=("sod", "prn"))
    assert j.height == k.height > 0
    # IS-GPS-200's delay against gLAB's variant of it (tests/sbas/test_klobuchar.py): within 12 cm
    assert float((j["iono"] - j["iono_glab"]).abs().max()) < 0.15
    # tau_vert changes at 55 deg geomagnetic latitude, where gLAB's exact latitude and IS-GPS-200's
    # approximation can disagree: one row here (6 m against 4.5 m); elsewhere the sigmas agree
    mag = np.rad2deg(geomagnetic_latitude(lat, lon, np.deg2rad(j["elevation"]), np.deg2rad(j["azimuth"])))
    edge = np.abs(np.abs(mag) - 55.0) < 0.1
    assert edge.sum() == 1 and j.filter(edge)["sigma_uire"][0] > j.filter(edge)["sigma_uire_glab"][0]
    ok = j.filter(~edge)
    assert float((ok["sigma_uire"] - ok["sigma_uire_glab"]).abs().max()) < 0.001
    assert float((ok["sigma"] - ok["sigma_glab"]).abs().max()) < 0.005
    # epochs with gLAB's satellites, away from that row: the same HPL (K_H = 6.18)
    used = a.filter("used").group_by("sod").len()
    full = var.group_by("sod").len().join(used, on="sod", suffix="_ours")
    full = full.filter(pl.col("len") == pl.col("len_ours"))
    e = _sod(after.epochs).join(out, on="sod", suffix="_glab").join(full, on="sod")
    e = e.filter(~pl.col("sod").is_in(j.filter(edge)["sod"].implode()))
    assert e["sod"].is_in(k["sod"].implode()).sum() > 10  # epochs that hold a Klobuchar row
    assert float((e["hpl"] - e["hpl_glab"]).abs().max()) < 0.001


def test_npa_klobuchar_after_the_igp_mask_times_out():
    _, msgs = _evening_inputs()
    cut = _without(msgs, ("igp_mask",), "19:45:00", "20:30:00")  # MT 18 time-out: 1200 s
    late = pl.col("time").is_between(pl.datetime(2019, 1, 14, 20, 10), pl.datetime(2019, 1, 14, 20, 25))
    none = _run(cut, "NPA").satellites.filter(late)
    klob = _run(cut, "NPA", klobuchar=_coefficients()).satellites.filter(late)
    assert (none["reason"] == "iono_mask_timeout").sum() > 20
    timed_out = none["reason"] == "iono_mask_timeout"
    assert klob.filter(timed_out)["used"].all()
    assert (klob.filter(timed_out)["iono_mode"] == IONO_MODE_KLOBUCHAR).all()


def test_pa_never_uses_the_broadcast_model():
    _, msgs = _evening_inputs()
    plain, given = _run(msgs, "PA"), _run(msgs, "PA", klobuchar=_coefficients())
    for x, y in ((plain.epochs, given.epochs), (plain.satellites, given.satellites)):
        bx, by = io.BytesIO(), io.BytesIO()
        x.write_ipc(bx)
        y.write_ipc(by)
        assert bx.getvalue() == by.getvalue()
    assert "klobuchar" not in given.counts and given.counts == plain.counts
    assert (given.satellites["reason"] == "iono_outside_triangle").sum() > 0


def _without(msgs, tables: tuple[str, ...], first: str, last: str):
    """The messages with the rows of ``tables`` (all tables if empty, the log included, so that the
    messages count as lost) between two times of 2019-01-14 removed."""
    t0, t1 = (dt.datetime.fromisoformat(f"2019-01-14T{x}") for x in (first, last))
    keep = ~pl.col("time").is_between(t0, t1)
    out = {k: v.filter(keep) if not tables or k in tables else v for k, v in msgs.tables().items()}
    return type(msgs)(**out, counts=msgs.counts)


def test_npa_keeps_satellites_through_a_short_message_gap():
    _, msgs = _evening_inputs()
    cut = _without(msgs, (), "20:29:51", "20:30:00")  # ten seconds of nothing before the epoch
    at = pl.datetime(2019, 1, 14, 20, 30, 0)
    pa = _run(cut, "PA").satellites.filter(pl.col("time") == at)
    npa = _run(cut, "NPA").satellites.filter(pl.col("time") == at)
    assert not pa["used"].any() and (pa["reason"] == "messages_lost").sum() > 0
    assert npa["used"].sum() >= 5  # fast corrections 10 s old: within every NPA time-out


def test_npa_long_term_correction_past_its_pa_timeout_adds_eps_er():
    _, msgs = _evening_inputs()
    deg = msgs.degradation.with_columns(cer=pl.lit(2.5))  # EGNOS broadcasts C_er = 0; give it a value
    cut = _without(type(msgs)(**(msgs.tables() | {"degradation": deg}), counts=msgs.counts),
                   ("long_term",), "20:30:00", "20:36:00")  # fmt: skip
    late = pl.col("time").is_between(
        pl.datetime(2019, 1, 14, 20, 34, 30), pl.datetime(2019, 1, 14, 20, 35, 30)
    )
    pa = _run(cut, "PA").satellites.filter(late)
    npa = _run(cut, "NPA").satellites.filter(late)
    assert (pa["reason"] == "long_term_timeout").sum() > 0  # 270-330 s old: past 240 s
    assert not (npa["reason"] == "long_term_timeout").any()  # ... but within 360 s
    used = npa.filter("used")
    assert used.height > 0 and (used["eps_er"] == 2.5).all()
    before = _run(cut, "NPA").satellites.filter(pl.col("time") < pl.datetime(2019, 1, 14, 20, 33, 0), "used")
    assert (before["eps_er"] == 0).all()


def test_npa_without_mt10_uses_the_8_m_sigma_flt():
    _, msgs = _evening_inputs()
    cut = _without(msgs, ("degradation",), "19:00:00", "23:00:00")
    pa = _run(cut, "PA").satellites
    npa = _run(cut, "NPA").satellites.filter("used")
    assert not pa["used"].any() and (pa["reason"] == "no_mt10").sum() > 0
    assert npa.height > 0
    np.testing.assert_allclose(npa["sigma_flt"], npa["sigma_udre"] * npa["delta_udre"] + 8.0, rtol=1e-12)
    assert (npa["eps_fc"] == 0).all() and (npa["eps_ltc"] == 0).all()


# --- MT 28 clock-ephemeris covariance (DO-229D A.4.4.16, A.4.5.1.1) ----------------------------------------
R_NAMES = ("r11", "r12", "r13", "r14", "r22", "r23", "r24", "r33", "r34", "r44")


@functools.cache
def _msas_covariance() -> pl.DataFrame:
    return decode(read_ems([DATA / "msas" / "ubx_20080526_sbas.ems.gz"])[0]).covariance


def _delta_udre_numpy(row: dict, los: np.ndarray, ccov: float) -> float:
    """sqrt(I^T C I) + C_cov 2^(scale_exp - 5), with C = R^T R from the upper-triangular R."""
    r = np.zeros((4, 4))
    r[np.triu_indices(4)] = [row[n] for n in R_NAMES]
    c = r.T @ r
    i = np.append(los, 1.0)
    return float(np.sqrt(i @ c @ i) + ccov * 2.0 ** (row["scale_exp"] - 5))


def test_mt28_delta_udre_from_real_msas_messages():
    cov = _msas_covariance()
    assert cov.height == 50 and cov["scale_exp"].n_unique() > 1  # 25 messages, two satellites each
    # the decoder's scaling: every stored element is an integer number of 2^(scale_exp - 5)
    lsb = 2.0 ** (pl.col("scale_exp").cast(pl.Float64) - 5)
    raw = cov.select(pl.col(n) / lsb for n in R_NAMES).to_numpy()
    assert np.array_equal(raw, np.round(raw)) and (raw[:, [0, 4, 7, 9]] >= 0).all()
    rng = np.random.default_rng(28)
    los = rng.normal(size=(cov.height, 3))
    los /= np.linalg.norm(los, axis=1, keepdims=True)
    ccov = np.full(cov.height, 0.3)
    ours = _covariance_delta(cov, np.arange(cov.height), los, ccov)
    expected = [_delta_udre_numpy(row, los[k], 0.3) for k, row in enumerate(cov.iter_rows(named=True))]
    np.testing.assert_allclose(ours, expected, rtol=1e-12)
    assert np.isnan(_covariance_delta(cov, np.array([-1]), los[:1], ccov[:1])).all()


def _with_mt28(msgs, skip_prn: int, stop: dict[int, str]):
    """EGNOS messages without MT 27 and with MT 28 built from the MSAS R factors: every 120 s for every GPS
    satellite of the mask except ``skip_prn``, until ``stop[prn]`` (a time of 2019-01-14) for some."""
    msas = _msas_covariance()
    gps = msgs.mask.filter(pl.col("system") == "GPS").unique(("iodp", "position", "sv")).sort("position")
    t0 = dt.datetime(2019, 1, 14, 19, 29)
    rows = []
    for j in range(82):
        t = t0 + dt.timedelta(seconds=120 * j)
        for k, (iodp, pos, sv) in enumerate(gps.select("iodp", "position", "sv").iter_rows()):
            if sv == skip_prn or (sv in stop and t > dt.datetime.fromisoformat(f"2019-01-14T{stop[sv]}")):
                continue
            src = msas.row(k % msas.height, named=True)
            rows.append({"time": t, "geo": 123, "iodp": iodp, "position": pos, "scale_exp": src["scale_exp"]}
                        | {n: src[n] for n in R_NAMES})  # fmt: skip
    cov = pl.DataFrame(rows).cast(msgs.covariance.schema).select(msgs.covariance.columns)
    deg = msgs.degradation.with_columns(ccovariance=pl.lit(0.4), cer=pl.lit(2.5))
    tables = msgs.tables() | {"covariance": cov, "degradation": deg, "service": msgs.service.clear(),
                              "service_regions": msgs.service_regions.clear()}  # fmt: skip
    return type(msgs)(**tables, counts=msgs.counts), cov, gps


def _los_ecef(sats: pl.DataFrame, ref: tuple[float, float, float]) -> np.ndarray:
    """Unit line of sight in ECEF from the reported elevation and azimuth (ENU at the reference)."""
    lat, lon, _ = pymap3d.ecef2geodetic(*ref, deg=False)
    el, az = np.deg2rad(sats["elevation"].to_numpy()), np.deg2rad(sats["azimuth"].to_numpy())
    enu = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)
    rot = np.array([[-np.sin(lon), -np.sin(lat) * np.cos(lon), np.cos(lat) * np.cos(lon)],
                    [np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat) * np.sin(lon)],
                    [0.0, np.cos(lat), np.sin(lat)]])  # fmt: skip
    return enu @ rot.T


def test_mt28_end_to_end_delta_udre_and_timeouts():
    obs, msgs = _evening_inputs()
    m28, cov, gps = _with_mt28(msgs, skip_prn=5, stop={21: "20:31:00"})
    pa = _run(m28, "PA").satellites
    used = pa.filter("used", pl.col("time").dt.minute() % 5 == 0, pl.col("time").dt.second() == 0)
    assert used.height > 200 and (used["delta_udre"] > 1).all()
    pos = gps.filter(pl.col("sv").is_in(used["prn"].cast(pl.Int64).implode()))
    los = _los_ecef(used, obs.header.approx_position)
    for k, row in enumerate(used.iter_rows(named=True)):
        p = int(pos.filter(pl.col("sv") == row["prn"])["position"][0])
        c = cov.filter(pl.col("position") == p, pl.col("time") <= row["time"] - dt.timedelta(seconds=0.12))
        expected = _delta_udre_numpy(c.row(-1, named=True), los[k], 0.4)
        assert row["delta_udre"] == pytest.approx(expected, rel=1e-7), row["prn"]
    # PRN 5 has no MT 28 while MT 28 is in use: no PA; PRN 21's last MT 28 (20:31) times out after 240 s
    assert set(pa.filter(pl.col("prn") == 5, pl.col("elevation") > 10)["reason"]) == {"no_mt28"}
    late = pl.col("time").is_between(pl.datetime(2019, 1, 14, 20, 35, 30),
                                     pl.datetime(2019, 1, 14, 20, 36, 30))  # fmt: skip
    p21 = pl.col("prn") == 21
    assert pa.filter(p21, late).height == 3 and set(pa.filter(p21, late)["reason"]) == {"mt28_timeout"}
    npa = _run(m28, "NPA").satellites
    n6 = npa.filter(p21, late)
    assert n6["used"].all() and (n6["eps_er"] == 2.5).all() and (n6["delta_udre"] > 1).all()  # 240-360 s
    after = npa.filter(p21, pl.col("time") > pl.datetime(2019, 1, 14, 20, 37, 30))  # past 360 s: delta-UDRE 1
    assert after.height > 0 and (after["delta_udre"] == 1).all()
    assert (npa.filter(pl.col("prn") == 5)["delta_udre"] == 1).all()
    # MT 27 and MT 28 both held: delta-UDRE 1 (an SBAS sends only one of them)
    both = type(m28)(**(m28.tables() | {"service": msgs.service, "service_regions": msgs.service_regions}),
                     counts=msgs.counts)  # fmt: skip
    b = _run(both, "PA").satellites.filter("used", pl.col("time") > pl.datetime(2019, 1, 14, 19, 33))
    assert b.height > 0 and (b["delta_udre"] == 1).all()


# --- MT 27 service message (DO-229D A.4.4.13) -----------------------------------------------------------
def _mt27(messages: list[dict], regions: list[tuple]) -> tuple[pl.DataFrame, pl.DataFrame]:
    """Service and region tables as the decoder makes them; ``regions``: (message index, lat1, lon1,
    lat2, lon2, square)."""
    t0 = dt.datetime(2019, 1, 14, 19, 0)
    s = pl.DataFrame([{"time": t0 + dt.timedelta(seconds=10 * k), "geo": 123,
                       "n_regions": sum(r[0] == k for r in regions)} | m
                      for k, m in enumerate(messages)])  # fmt: skip
    factor = dict(enumerate(DELTA_UDRE))
    s = s.with_columns(dudre_in=pl.col("dudrei_in").replace_strict(factor),
                       dudre_out=pl.col("dudrei_out").replace_strict(factor))  # fmt: skip
    reg = pl.DataFrame(
        [{"time": s["time"][k], "geo": 123, "iods": messages[k]["iods"],
          "message_number": messages[k]["message_number"], "region": j + 1, "lat1": a, "lon1": b,
          "lat2": c, "lon2": d, "square": sq} for j, (k, a, b, c, d, sq) in enumerate(regions)],
    )  # fmt: skip
    return s, reg


def _msg(iods, n, number, priority, din, dout):
    return {"iods": iods, "n_messages": n, "message_number": number, "priority": priority,
            "dudrei_in": din, "dudrei_out": dout}  # fmt: skip


def test_mt27_triangle_third_corner_and_squares():
    _, reg = _mt27([_msg(0, 1, 1, 0, 0, 15)], [(0, 40, 0, 50, 10, False), (0, 40, 0, 50, 10, True)])
    # triangle (40, 0), (50, 10) and the third corner (lat1, lon2) = (40, 10): the south-east half
    assert _in_regions(reg, 42.0, 8.0).tolist() == [True, True]
    assert _in_regions(reg, 48.0, 2.0).tolist() == [False, True]
    assert _in_regions(reg, 45.0, 5.0).tolist() == [True, True]  # on the hypotenuse
    assert _in_regions(reg, 39.0, 5.0).tolist() == [False, False]


def test_mt27_priority_ties_outside_and_incomplete_sets():
    msgs = [_msg(1, 2, 1, 1, 3, 9), _msg(1, 2, 2, 2, 5, 9),  # IODS 1: message 2 has the higher priority
            _msg(2, 2, 1, 0, 1, 12),  # IODS 2 incomplete: IODS 1 stays in force
            _msg(2, 2, 2, 0, 2, 12)]  # fmt: skip
    regions = [(0, 40, 0, 50, 10, True), (1, 44, 4, 46, 6, True), (2, 40, 0, 50, 10, True),
               (3, 30, -10, 55, 20, True), (3, 0, 0, 1, 1, True)]  # fmt: skip
    s, reg = _mt27(msgs, regions)
    v, t_set = _service_sets(s, reg, 45.0, 5.0)
    assert np.isnan(v[0])  # one message of two
    assert v[1] == DELTA_UDRE[5] and v[2] == DELTA_UDRE[5]  # the higher-priority region
    assert v[3] == DELTA_UDRE[1]  # equal priorities: the smaller delta-UDRE_in
    st = s["time"].dt.epoch("us").to_numpy()
    assert t_set[1] == st[0] and t_set[2] == st[0] and t_set[3] == st[2]
    v_out, _ = _service_sets(s, reg, 60.0, 5.0)
    assert v_out[1] == DELTA_UDRE[9] and v_out[3] == DELTA_UDRE[12]  # outside every region


def _with_service(msgs, s: pl.DataFrame, reg: pl.DataFrame):
    new = {
        "service": s.select(msgs.service.columns).cast(msgs.service.schema),
        "service_regions": reg.select(msgs.service_regions.columns).cast(msgs.service_regions.schema),
    }
    return type(msgs)(**(msgs.tables() | new), counts=msgs.counts)


def test_mt27_incomplete_set_loses_pa_and_gives_one_in_npa():
    _, msgs = _evening_inputs()
    s, reg = _mt27([_msg(3, 2, 1, 0, 4, 4)], [(0, -80, -170, 80, 170, True)])
    cut = _with_service(msgs, s, reg)
    pa = _run(cut, "PA").satellites
    assert not pa["used"].any() and (pa["reason"] == "mt27_incomplete").sum() > 0
    npa = _run(cut, "NPA").satellites.filter("used")
    assert npa.height > 0 and (npa["delta_udre"] == 1).all()
    s2, reg2 = _mt27([_msg(3, 1, 1, 0, 4, 9)], [(0, -80, -170, 80, 170, True)])  # complete: inside, 2.0
    full = _with_service(msgs, s2, reg2)
    u = _run(full, "PA").satellites.filter("used")
    assert u.height > 0 and (u["delta_udre"] == DELTA_UDRE[4]).all()


# --- IODF = 3 alarm in the range-rate correction (DO-229D A.4.4.3, A.4.5.1.2) ------------------------------
def test_earliest_within_picks_the_largest_gap_below_the_window():
    key = np.array([1, 1, 1, 1, 2, 1])
    t = np.array([0, 4, 8, 12, 11, 16]) * 1_000_000
    got = earliest_within(key, t, np.array([3, 5, 0, -1, 4]), np.array([9.0, 9.0, 9.0, 9.0, 9.0]) * 1e6, 0)
    assert got.tolist() == [1, 2, -1, -1, -1]  # 12 s: 8 s back (4 s); 16 s: 8 s back; first row: none


def test_iodf3_alarm_takes_the_previous_prc_closest_to_half_the_timeout():
    _, msgs = _evening_inputs()
    ai11 = msgs.fc_degradation.with_columns(ai_index=pl.lit(11, pl.UInt8), ai=pl.lit(AI[11]))
    deg = msgs.degradation.with_columns(brrc=pl.lit(0.2))
    sel = (pl.col("position") == 28) & (pl.col("iodp") == 0)  # PRN 29
    # distinct PRCs so that the RRC tells which previous PRC was taken (the real ones barely move)
    f = msgs.fast.with_columns(prc=pl.when(sel).then(0.125 * (pl.int_range(pl.len()) % 7)).otherwise("prc"))
    tags = f.filter(sel)["time"].to_list()
    prc = dict(zip(tags, f.filter(sel)["prc"].to_list(), strict=True))
    iodf = dict(zip(tags, f.filter(sel)["iodf"].to_list(), strict=True))
    sec = dt.timedelta(seconds=1)

    def current(t):  # the PRC in force at epoch t: the last tag at least the 0.12 s flight time before
        return max(x for x in tags if x <= t - 0.12 * sec)

    def regular(t):  # PRCs 4, 8 and 12 s before the current one
        return all(current(t) - k * sec in prc for k in (4, 8, 12))

    grid = [dt.datetime(2019, 1, 14, 20, 0) + 30 * k * sec for k in range(60)]
    e1, e2, e3 = next(g for g in zip(grid, grid[1:], grid[2:], strict=False) if all(map(regular, g)))
    alarms = [current(e1), current(e2) - 4 * sec]  # current IODF 3 at e1, previous IODF 3 at e2
    fast = f.with_columns(iodf=pl.when(sel & pl.col("time").is_in(alarms)).then(3).otherwise("iodf")
                          .cast(f["iodf"].dtype))  # fmt: skip
    m = type(msgs)(**(msgs.tables() | {"fast": fast, "fc_degradation": ai11, "degradation": deg}),
                   counts=msgs.counts)  # fmt: skip
    sats = _run(m, "PA").satellites.filter(pl.col("prn") == 29)
    half = FC_TIMEOUT_PA[11] / 2  # I_fc = 18 s for every satellite; PRCs every 4 s
    for e in (e1, e2):  # alarm: the previous PRC 8 s back (the largest gap below 9 s)
        r = sats.filter(pl.col("time") == e).row(0, named=True)
        c = current(e)
        t_tof = (e - c).total_seconds() + 1.0
        assert r["used"]
        assert r["rrc"] == pytest.approx((prc[c] - prc[c - 8 * sec]) / 8, abs=1e-12)
        assert r["eps_rrc"] == pytest.approx((AI[11] * abs(8 - half) / 2 + 0.2 / 8) * t_tof, rel=1e-9)
    # no alarm at e3: the last two PRCs; eps_rrc 0 when their IODFs are in sequence
    c = current(e3)
    r = sats.filter(pl.col("time") == e3).row(0, named=True)
    assert r["rrc"] == pytest.approx((prc[c] - prc[c - 4 * sec]) / 4, abs=1e-12)
    in_seq = (iodf[c] - iodf[c - 4 * sec]) % 3 == 1
    assert in_seq and r["eps_rrc"] == 0


def test_grid_states_of_a_chunk_are_the_latest_values_of_the_whole_day():
    """The ionospheric grid table of a few minutes of epochs (the maps' chunks) is built from the MT 26 rows
    that can be in force then only, and holds per epoch and IGP the row an as-of over the whole day gives:
    the largest tag <= t, the last row among equal tags; an IGP last broadcast hours before keeps that row."""
    frames, _ = read_ems([DATA / "network" / "egnos123_2019014.ems.gz"])
    g = decode(frames).iono
    tg = times_us(g["time"])
    gkey = g["band"].to_numpy().astype(np.int64) * 201 + g["igp"].to_numpy().astype(np.int64)
    noon = int(np.datetime64("2019-01-14T12:00:00", "us").astype(np.int64))
    old = gkey[0]  # silenced from 06:00: its value in force at noon is hours old
    keep = (gkey != old) | (tg < noon - 6 * 3600 * 10**6)
    tg, gkey = tg[keep], gkey[keep]
    before = np.flatnonzero(gkey == old)[-1]
    inside = np.flatnonzero((tg > noon) & (tg < noon + 60 * 10**6))[0]
    tg, gkey = np.append(tg, tg[[before, inside]]), np.append(gkey, gkey[[before, inside]])  # equal tags
    ep_t = np.sort(np.append(noon + 7 * 10**6 * np.arange(60), tg[inside]))  # an epoch at a tag too
    cells = _GridStates(gkey, tg, ep_t, np.zeros(ep_t.size, np.int64))
    keys = np.unique(gkey)
    got = cells.table[cells.state_ep][:, cells.column[keys]]
    order = np.lexsort((np.arange(tg.size), tg, gkey))
    for e, t in enumerate(ep_t):
        avail = order[tg[order] <= t]
        last = np.append(gkey[avail[1:]] != gkey[avail[:-1]], True)
        want = np.full(keys.size, -1)
        want[np.searchsorted(keys, gkey[avail[last]])] = avail[last]
        np.testing.assert_array_equal(got[e], want)
    assert got[0, np.searchsorted(keys, old)] == tg.size - 2  # the hours-old value, its later duplicate
    assert (got == tg.size - 1).any()  # the in-chunk tie resolved to the later row
    assert cells.table.shape[0] <= 61  # states: the chunk's, not the day's
