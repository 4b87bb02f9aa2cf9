"""GPS broadcast ionosphere (IS-GPS-200 20.3.3.5.2.5) and its SBAS sigma (DO-229D J.2.3).

By hand from the IS-GPS-200 steps, and against gLAB v6 on the rows of the evening Toulouse window
where gLAB's NPA used its Klobuchar model (tests/data/sbas/engine/PROVENANCE.md).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest

from overbound.io.rinex_nav import SPEED_OF_LIGHT, read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.sbas.engine import SbasOptions
from overbound.sbas.iono import obliquity
from overbound.sbas.klobuchar import geomagnetic_latitude, klobuchar_delay, klobuchar_sigma2, tau_vert
from overbound.sbas.run import process, read_inputs

FIX = Path(__file__).resolve().parents[1] / "data" / "sbas" / "engine"
NAV = FIX / "brdc0140.19n.gz"
OBS = FIX / "SYNT0140_1930-2210.19o.gz"
EMS = FIX / "ems_1930-2210.ems.gz"
C = SPEED_OF_LIGHT
ZERO = (0.0, 0.0, 0.0)


# --- IS-GPS-200 by hand -------------------------------------------------------------------------------
def test_zenith_at_14h_local_is_f_times_5ns_plus_amp():
    # zenith (E = 0.5 semicircle): F = 1 + 16 (0.53 - 0.5)^3 = 1.000432; azimuth 0 at longitude 0:
    # lambda_i = 0, so t = t_GPS; at 50400 s x = 0 and T = F (5 ns + AMP), AMP = alpha_0 alone
    f = 1.0 + 16.0 * 0.03**3
    d = klobuchar_delay((1e-8, 0, 0, 0), (72000.0, 0, 0, 0), 0.7, 0.0, np.pi / 2, 0.0, 50_400.0)
    assert d == pytest.approx(f * 15e-9 * C, rel=1e-13)  # 4.4988 m
    # the day (and the week) do not matter: only t modulo 86400 s
    t = 50_400.0 + 3 * 86_400
    later = klobuchar_delay((1e-8, 0, 0, 0), (72000.0, 0, 0, 0), 0.7, 0.0, np.pi / 2, 0.0, t)
    assert later == pytest.approx(d, rel=1e-13)


def test_afternoon_uses_the_fourth_order_cosine_and_night_the_5ns_floor():
    f = 1.0 + 16.0 * 0.03**3
    a, b = (1e-8, 0, 0, 0), (72000.0, 0, 0, 0)
    # 16:00 local: x = 2 pi 7200 / 72000 = 0.2 pi = 0.62832; 1 - x^2/2 + x^4/24 = 1 - 0.19739 + 0.00649
    x = 0.2 * np.pi
    d = klobuchar_delay(a, b, 0.7, 0.0, np.pi / 2, 0.0, 57_600.0)
    assert d == pytest.approx(f * (5e-9 + 1e-8 * (1 - x**2 / 2 + x**4 / 24)) * C, rel=1e-13)
    assert d != pytest.approx(f * (5e-9 + 1e-8 * np.cos(x)) * C, rel=1e-6)  # not the exact cosine
    # 02:00 local: x = 2 pi (7200 - 50400) / 72000 = -3.77, |x| >= 1.57: F 5 ns only
    assert klobuchar_delay(a, b, 0.7, 0.0, np.pi / 2, 0.0, 7_200.0) == pytest.approx(f * 5e-9 * C, rel=1e-13)


def test_amplitude_and_period_limits():
    f = 1.0 + 16.0 * 0.03**3
    # AMP < 0 is set to 0
    d = klobuchar_delay((-1e-8, 0, 0, 0), (72000.0, 0, 0, 0), 0.7, 0.0, np.pi / 2, 0.0, 50_400.0)
    assert d == pytest.approx(f * 5e-9 * C, rel=1e-13)
    # PER below 72000 s is 72000 s: at 16:00 local the same as with 72000
    low = klobuchar_delay((1e-8, 0, 0, 0), (50000.0, 0, 0, 0), 0.7, 0.0, np.pi / 2, 0.0, 57_600.0)
    ref = klobuchar_delay((1e-8, 0, 0, 0), (72000.0, 0, 0, 0), 0.7, 0.0, np.pi / 2, 0.0, 57_600.0)
    assert low == pytest.approx(ref, rel=1e-13)


def test_pierce_point_and_geomagnetic_latitude_by_hand():
    # 45 N 0 E, elevation 30 deg (E = 1/6 semicircle), azimuth 90 deg (east):
    # psi = 0.0137 / (1/6 + 0.11) - 0.022 = 0.027518; phi_i = 0.25 + psi cos(90 deg) = 0.25;
    # lambda_i = 0 + psi sin(90 deg) / cos(0.25 pi) = 0.038916; phi_m = 0.25 + 0.064 cos(pi (0.038916 -
    # 1.617)) = 0.25 + 0.064 cos(-284.055 deg) = 0.25 + 0.064 x 0.24287 = 0.265544 semicircle = 47.798 deg
    e = 1.0 / 6.0
    psi = 0.0137 / (e + 0.11) - 0.022
    lam_i = psi / np.cos(0.25 * np.pi)
    phi_m = 0.25 + 0.064 * np.cos(np.pi * (lam_i - 1.617))
    got = geomagnetic_latitude(np.pi / 4, 0.0, np.pi / 6, np.pi / 2)
    assert got == pytest.approx(np.pi * phi_m, rel=1e-13)
    assert np.rad2deg(got) == pytest.approx(47.798, abs=0.001)
    # delay with a latitude-dependent amplitude: AMP = alpha_1 phi_m; local time t_GPS + 43200 lambda_i
    t = 50_400.0 - 4.32e4 * lam_i  # local 14:00 at the pierce point: x = 0
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    d = klobuchar_delay((0.0, 2e-8, 0, 0), (72000.0, 0, 0, 0), np.pi / 4, 0.0, np.pi / 6, np.pi / 2, t)
    assert d == pytest.approx(f * (5e-9 + 2e-8 * phi_m) * C, rel=1e-12)
    # the pierce-point latitude is limited to +-0.416 semicircle (74.9 deg): near the pole, looking north
    assert geomagnetic_latitude(np.deg2rad(85.0), 0.0, np.pi / 2, 0.0) == pytest.approx(
        np.pi * (0.416 + 0.064 * np.cos(np.pi * (0.0 - 1.617))), rel=1e-13
    )


def test_tau_vert_and_sigma_of_j23():
    lat = np.deg2rad(np.array([0.0, 20.0, 20.01, 40.0, 55.0, 55.01, -70.0]))
    assert tau_vert(lat).tolist() == [9.0, 9.0, 4.5, 4.5, 4.5, 6.0, 6.0]
    el = np.deg2rad(np.array([10.0, 10.0]))
    fpp = obliquity(el)
    # at 10 deg F_pp = 2.79: a 3 m delay gives (F_pp 4.5 m)^2 = 12.56^2, an 80 m one (80 / 5)^2 = 16^2
    s2 = klobuchar_sigma2(np.array([3.0, 80.0]), el, np.deg2rad(np.array([40.0, 40.0])))
    assert s2[0] == pytest.approx((fpp[0] * 4.5) ** 2, rel=1e-14)
    assert s2[1] == pytest.approx(16.0**2, rel=1e-14) and 16.0 > fpp[1] * 4.5 > 12.0


def test_bad_coefficients_are_refused():
    with pytest.raises(ValueError, match="alpha"):
        klobuchar_delay((1e-8, 0, 0), (72000.0, 0, 0, 0), 0.0, 0.0, 1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="beta"):
        klobuchar_delay((1e-8, 0, 0, 0), (np.nan, 0, 0, 0), 0.0, 0.0, 1.0, 0.0, 0.0)


# --- against gLAB ---------------------------------------------------------------------------------------
def _glab_klobuchar_rows() -> pl.DataFrame:
    """gLAB's SBASCORR lines where its ionosphere is Klobuchar: time, PRN, elevation, azimuth, delay."""
    text = gzip.decompress((FIX / "glab_synt_1930-2210_npa_klobuchar.out.gz").read_bytes()).decode()
    rows = [ln.split() for ln in text.splitlines()]
    assert rows and all(r[50] == "1" for r in rows)
    return pl.DataFrame(
        [(float(r[3]), int(r[6]), float(r[11]), float(r[12]), float(r[24])) for r in rows],
        schema=["sod", "prn", "elevation", "azimuth", "iono"], orient="row",
    )  # fmt: skip


def _glab_sigma_uire() -> pl.DataFrame:
    lines = gzip.decompress((FIX / "glab_synt_1930-2210_npa.out.gz").read_bytes()).decode().splitlines()
    rows = [ln.split() for ln in lines if ln.startswith("SBASVAR")]
    return pl.DataFrame([(float(r[3]), int(r[6]), float(r[25])) for r in rows],
                        schema=["sod", "prn", "sigma_uire"], orient="row")  # fmt: skip


def _glab_variant(alpha, beta, lat, lon, el, az, sod):
    """gLAB's Klobuchar variant (spherical pierce point at 350 km, geomagnetic latitude from the pole
    78.3 N 291 E, exact obliquity, exact cosine), written from those formulas to explain the difference
    from IS-GPS-200: returns (slant delay m, geomagnetic latitude rad)."""
    r, h = 6378137.0, 350_000.0
    psi = np.pi / 2 - el - np.arcsin(r / (r + h) * np.cos(el))
    lat_i = np.arcsin(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(az))
    lon_i = lon + psi * np.sin(az) / np.cos(lat_i)
    pole_lat, pole_lon = np.deg2rad(78.3), np.deg2rad(291.0)
    cos_lon = np.cos(lon_i - pole_lon)
    mag = np.arcsin(np.sin(lat_i) * np.sin(pole_lat) + np.cos(lat_i) * np.cos(pole_lat) * cos_lon)
    t = np.mod(43_200.0 * lon_i / np.pi + sod, 86_400.0)
    amp = np.maximum(np.polynomial.polynomial.polyval(mag / np.pi, alpha), 0.0)
    per = np.maximum(np.polynomial.polynomial.polyval(mag / np.pi, beta), 72_000.0)
    x = 2 * np.pi * (t - 50_400.0) / per
    slant = 1.0 / np.sqrt(1.0 - (r / (r + h) * np.cos(el)) ** 2)
    return slant * (5e-9 + np.where(np.abs(x) <= 1.57, amp * np.cos(x), 0.0)) * C, mag


def test_against_glab_klobuchar_rows():
    nav, _ = read_rinex_nav(NAV)
    alpha, beta = nav.header.ion_alpha, nav.header.ion_beta
    obs, _ = read_rinex_obs(OBS)
    lat, lon, _ = pymap3d.ecef2geodetic(*obs.header.approx_position, deg=False)
    g = _glab_klobuchar_rows().join(_glab_sigma_uire(), on=("sod", "prn"))
    assert g.height == 48
    el, az = np.deg2rad(g["elevation"].to_numpy()), np.deg2rad(g["azimuth"].to_numpy())
    sod = g["sod"].to_numpy()
    ours = klobuchar_delay(alpha, beta, lat, lon, el, az, sod + 86_400.0)  # Monday: day 1 of the GPS week
    mag = geomagnetic_latitude(lat, lon, el, az)
    sigma = np.sqrt(klobuchar_sigma2(ours, el, mag))
    variant, mag_glab = _glab_variant(np.array(alpha), np.array(beta), lat, lon, el, az, sod)
    glab = g["iono"].to_numpy()
    # the variant reproduces gLAB's delays (printed to 0.1 mm) from the same inputs ...
    assert np.abs(variant - glab).max() < 0.001
    # ... and IS-GPS-200's delay is within its model difference of it (12 cm here, at 5-70 deg)
    assert 0.05 < np.abs(ours - glab).max() < 0.15
    # sigma: the same wherever both geomagnetic latitudes give the same tau_vert
    same = tau_vert(mag) == tau_vert(mag_glab)
    assert np.abs(sigma - g["sigma_uire"].to_numpy())[same].max() < 0.001
    # one row (PRN 6, 19:31:30, 9 deg) has phi_m 55.06 deg by IS-GPS-200 and 54.98 deg by gLAB: 6 m vs 4.5 m
    assert (~same).sum() == 1 and g.filter(~same)["prn"].to_list() == [6]
    assert sigma[~same][0] / g.filter(~same)["sigma_uire"][0] == pytest.approx(6.0 / 4.5, rel=1e-4)


# --- wiring: the navigation header's coefficients reach the engine -------------------------------------
def _without_ion_lines(tmp_path: Path) -> Path:
    text = gzip.decompress(NAV.read_bytes()).decode()
    lines = text.splitlines(keepends=True)
    kept = "".join(ln for ln in lines if ln[60:].strip() not in ("ION ALPHA", "ION BETA"))
    path = tmp_path / "brdc0140.19n"
    path.write_text(kept)
    return path


def test_process_passes_the_header_coefficients(tmp_path):
    nav, _ = read_rinex_nav(NAV)
    inp = read_inputs(OBS, NAV, EMS)
    assert inp.klobuchar == (nav.header.ion_alpha, nav.header.ion_beta)
    npa = process(OBS, NAV, EMS, options=SbasOptions(mode="NPA"))
    n = npa.counts["engine"]["klobuchar"]
    assert n > 0 and (npa.satellites["iono_mode"] == 5).sum() >= n
    assert "klobuchar" not in process(OBS, NAV, EMS).counts["engine"]  # PA: never
    bare = _without_ion_lines(tmp_path)
    assert read_inputs(OBS, bare, EMS).klobuchar is None
    none = process(OBS, bare, EMS, options=SbasOptions(mode="NPA"))
    assert none.counts["engine"]["klobuchar"] == "no coefficients"
    assert (none.satellites["iono_mode"] != 5).all()
    reasons = none.counts["engine"]["reasons"]
    assert reasons["no_iono"] + reasons["iono_outside_triangle"] >= n  # the rows keep their reasons
