"""The ceiling of a compiled (epoch, node, satellite) kernel for the service-volume maps (issue 15).

Usage: ``pip install numba && python bench/bench_sbas_map_ceiling.py [--epochs N] [--glab-rate R]``.

Not overbound's code and not a map: a measure of what the 10x-gLAB target of ``bench_sbas_map.py``
asks of the arithmetic alone. The real GPS constellation of the EGNOS day
(``tests/data/sbas/engine/brdc0140.19n.gz``, broadcast positions every 60 s), the 1 deg EGNOS area
(3266 nodes, height 0), mask 5 deg. Per (epoch, node, satellite), compiled by numba over
``prange(epochs x nodes)``: the line of sight in the node's ENU frame, the mask, elevation and
azimuth, the pierce point (DO-229D A.4.4.10.1), a bilinear interpolation of sigma2_UIVE in a 5 deg
cell table (a random table per epoch: no IGP selection, masks, time-outs or degradation), the
obliquity, the tropospheric and airborne variances (A.4.2.4, J.2.4) and sigma2_flt per satellite
given; per (epoch, node) the 4x4 normal matrix, its inverse, HPL and VPL (K = 6.0, 5.33). What the
real engine adds (IGP selection of A.4.4.10.2, MT 27/28 delta-UDRE at the node, every time-out,
the messages' decoding, the summary and the report) only costs more, so the printed rate is an
upper bound of a faithful kernel on this machine.

Printed: node-epochs per second on 1 and 2 threads, and the ratio to gLAB's SBAS plots mode
(``--glab-rate``: node-epochs/s of ``bench_sbas_map.py --glab``; default 129,299, measured on this
2-core machine on 2026-12-03).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numba as nb
import numpy as np

from overbound.io.rinex_nav import broadcast_state, read_rinex_nav, rotate_earth
from overbound.sbas.maps import EGNOS_AREA, MapGrid, _nearest_records, grid_points

NAV = Path(__file__).resolve().parents[1] / "tests" / "data" / "sbas" / "engine" / "brdc0140.19n.gz"
R_E, H_I = 6378136.3, 350_000.0  # DO-229D A.4.4.10.1: Earth radius and ionospheric shell height, m
DAY_US = int(np.datetime64("2019-01-14", "us").astype(np.int64))  # 00:00 GPS time


@nb.njit(parallel=True, cache=False)
def kernel(sat, sig2_flt, uive, lat, lon, rx, sin_mask, hpl, vpl):  # pragma: no cover - a measure
    n_t, n_s, n_p = sat.shape[0], sat.shape[1], lat.size
    for k in nb.prange(n_t * n_p):
        t, p = k // n_p, k % n_p
        sl, cl, so, co = np.sin(lat[p]), np.cos(lat[p]), np.sin(lon[p]), np.cos(lon[p])
        a00 = a01 = a02 = a03 = a11 = a12 = a13 = a22 = a23 = a33 = 0.0  # the normal matrix
        nsv = 0
        for s in range(n_s):
            if not np.isfinite(sat[t, s, 0]):
                continue
            dx, dy, dz = sat[t, s, 0] - rx[p, 0], sat[t, s, 1] - rx[p, 1], sat[t, s, 2] - rx[p, 2]
            r = np.sqrt(dx * dx + dy * dy + dz * dz)
            u = (cl * co * dx + cl * so * dy + sl * dz) / r
            if u < sin_mask:
                continue
            e = (-so * dx + co * dy) / r
            n = (-sl * co * dx - sl * so * dy + cl * dz) / r
            el, az = np.arcsin(u), np.arctan2(e, n)
            psi = np.pi / 2 - el - np.arcsin(R_E / (R_E + H_I) * np.cos(el))
            plat = np.arcsin(sl * np.cos(psi) + cl * np.sin(psi) * np.cos(az))
            plon = lon[p] + np.arcsin(np.sin(psi) * np.sin(az) / np.cos(plat))
            y, x = (np.degrees(plat) + 90.0) / 5.0, (np.degrees(plon) + 180.0) / 5.0
            iy, ix = min(max(int(y), 0), 34), int(x) % 71
            fy, fx = y - int(y), x - int(x)
            g = (uive[t, iy, ix] * (1 - fx) * (1 - fy) + uive[t, iy, ix + 1] * fx * (1 - fy)
                 + uive[t, iy + 1, ix] * (1 - fx) * fy + uive[t, iy + 1, ix + 1] * fx * fy)  # fmt: skip
            fpp2 = 1.0 / (1.0 - (R_E * np.cos(el) / (R_E + H_I)) ** 2)
            m_tropo = 1.001 / np.sqrt(0.002001 + u * u)
            s_mp = 0.13 + 0.53 * np.exp(-np.degrees(el) / 10.0)
            w = 1.0 / (sig2_flt[t, s] + fpp2 * g + 0.36**2 + s_mp * s_mp + (0.12 * m_tropo) ** 2)
            nsv += 1  # the row of G: (-e, -n, -u, 1)
            a00 += w * e * e
            a01 += w * e * n
            a02 += w * e * u
            a03 -= w * e
            a11 += w * n * n
            a12 += w * n * u
            a13 -= w * n
            a22 += w * u * u
            a23 -= w * u
            a33 += w
        if nsv < 4:
            hpl[k], vpl[k] = np.nan, np.nan
            continue
        d00, d11, d01, d22 = _inverse_enu(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33)
        d_major = (d00 + d11) / 2 + np.sqrt(((d00 - d11) / 2) ** 2 + d01**2)
        hpl[k], vpl[k] = 6.0 * np.sqrt(d_major), 5.33 * np.sqrt(d22)


@nb.njit(inline="always")
def _inverse_enu(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33):  # pragma: no cover
    """d_EE, d_NN, d_EN, d_UU of the inverse of a symmetric positive 4x4 matrix, by its Cholesky
    factor L (A = L L^T, inverse = M^T M with M = L^-1), in scalars: no allocation per node."""
    l00 = np.sqrt(a00)
    l10, l20, l30 = a01 / l00, a02 / l00, a03 / l00
    l11 = np.sqrt(a11 - l10 * l10)
    l21, l31 = (a12 - l20 * l10) / l11, (a13 - l30 * l10) / l11
    l22 = np.sqrt(a22 - l20 * l20 - l21 * l21)
    l32 = (a23 - l30 * l20 - l31 * l21) / l22
    l33 = np.sqrt(a33 - l30 * l30 - l31 * l31 - l32 * l32)
    m00, m11, m22 = 1 / l00, 1 / l11, 1 / l22  # (m33 enters no term below)
    m10 = -l10 * m00 / l11
    m20 = -(l20 * m00 + l21 * m10) / l22
    m21 = -l21 * m11 / l22
    m30 = -(l30 * m00 + l31 * m10 + l32 * m20) / l33
    m31 = -(l31 * m11 + l32 * m21) / l33
    m32 = -l32 * m22 / l33
    d00 = m00 * m00 + m10 * m10 + m20 * m20 + m30 * m30
    d11 = m11 * m11 + m21 * m21 + m31 * m31
    d01 = m10 * m11 + m20 * m21 + m30 * m31
    d22 = m22 * m22 + m32 * m32
    return d00, d11, d01, d22


def satellites(n_epochs: int) -> np.ndarray:
    """(epochs, 32, 3) ECEF positions of GPS PRN 1..32 every 60 s from the start of the day (NaN: none)."""
    eph, _ = read_rinex_nav(NAV)
    times = DAY_US + 60 * 10**6 * np.arange(n_epochs, dtype=np.int64)
    rec = _nearest_records(eph.table, times)
    out = np.full((n_epochs, 32, 3), np.nan)
    t_i, s_i = np.nonzero(rec >= 0)
    st = broadcast_state(eph.table, rec[t_i, s_i], times[t_i], -0.075)
    out[t_i, s_i] = rotate_earth(st.position, 0.075)
    return out


def check_inverse() -> None:
    """The scalar Cholesky inverse against numpy's on random normal matrices of 6-12 satellites."""
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(1000):
        los = rng.normal(size=(rng.integers(6, 13), 3))
        los /= np.linalg.norm(los, axis=1, keepdims=True)
        g = np.column_stack([-los, np.ones(len(los))])
        a = g.T @ np.diag(rng.uniform(0.05, 2.0, len(los))) @ g
        ref = np.linalg.inv(a)
        got = _inverse_enu.py_func(*(a[i, j] for i, j in ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2),
                                                           (1, 3), (2, 2), (2, 3), (3, 3))))  # fmt: skip
        want = (ref[0, 0], ref[1, 1], ref[0, 1], ref[2, 2])
        worst = max(
            worst, max(abs(x - y) / abs(ref[0, 0] + ref[1, 1]) for x, y in zip(got, want, strict=True))
        )
    print(f"scalar Cholesky inverse vs numpy.linalg.inv: largest relative difference {worst:.1e}")
    assert worst < 1e-9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=240, help="epochs every 60 s (default: 4 h)")
    ap.add_argument("--glab-rate", type=float, default=129_299.0)
    args = ap.parse_args()
    check_inverse()
    lat, lon, ecef = grid_points(MapGrid(*EGNOS_AREA, step=1.0))
    lat, lon = np.radians(lat), np.radians(lon)
    sat = satellites(args.epochs)
    rng = np.random.default_rng(0)
    sig2_flt = rng.uniform(0.5, 4.0, sat.shape[:2])
    uive = rng.uniform(0.1, 10.0, (args.epochs, 36, 72))
    hpl, vpl = np.empty(args.epochs * lat.size), np.empty(args.epochs * lat.size)
    sin_mask = float(np.sin(np.radians(5.0)))
    kernel(sat[:1], sig2_flt[:1], uive[:1], lat, lon, ecef, sin_mask, hpl, vpl)  # compile
    work = args.epochs * lat.size
    print(f"{lat.size} nodes x {args.epochs} epochs = {work:,} node-epochs; gLAB {args.glab_rate:,.0f}/s")
    for threads in (1, 2):
        nb.set_num_threads(threads)
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            kernel(sat, sig2_flt, uive, lat, lon, ecef, sin_mask, hpl, vpl)
            best = min(best, time.perf_counter() - t0)
        rate = work / best
        print(f"{threads} thread(s): {best:6.3f} s, {rate:>10,.0f} node-epochs/s, "
              f"{rate / args.glab_rate:5.2f}x gLAB (target 10x, with everything else)")  # fmt: skip
    solved = np.isfinite(vpl)
    print(f"solved {solved.mean():.3f} of node-epochs; median HPL {np.median(hpl[solved]):.1f} m, "
          f"VPL {np.median(vpl[solved]):.1f} m (fake variances: a sanity check only)")  # fmt: skip


if __name__ == "__main__":
    main()
