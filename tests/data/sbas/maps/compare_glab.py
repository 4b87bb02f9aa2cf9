"""Compare overbound's service-volume map of the EGNOS day with gLAB's (the files of this folder) on the
whole 2 deg grid at 60 s, as issue 15 asks; prints the figures quoted in tests/sbas/test_maps.py.

    python tests/data/sbas/maps/compare_glab.py [--workers N]   # from the repository root; 75 s, one core
"""

from __future__ import annotations

import argparse
import gzip
import time
from pathlib import Path

import numpy as np
import polars as pl

from overbound.campaign import campaign_client
from overbound.sbas.maps import MapGrid
from overbound.sbas_map import MapOptions, compute_map
from overbound.services import resolve_services

HERE = Path(__file__).resolve().parent
SBAS = HERE.parent


def glab(name: str) -> np.ndarray:
    lines = gzip.decompress((HERE / name).read_bytes()).decode().splitlines()
    return np.array([[float(x) for x in line.split()] for line in lines[3:] if line.strip()])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=0)
    args = ap.parse_args()
    options = MapOptions(
        grid=MapGrid(-30.0, 40.0, 25.0, 70.0, 2.0), services=resolve_services(["LPV", "LPV-200"])
    )
    client = campaign_client(workers=args.workers) if args.workers else None
    t0 = time.perf_counter()
    nav, ems = SBAS / "engine" / "brdc0140.19n.gz", SBAS / "network" / "egnos123_2019014.ems.gz"
    smap = compute_map(nav, ems, options, client=client)
    wall = time.perf_counter() - t0
    n = smap.lat_axis.size * smap.lon_axis.size
    rate = n * smap.times_us.size / wall
    print(f"{n} nodes x {smap.times_us.size} epochs in {wall:.1f} s ({rate:,.0f} node-epochs/s)")
    for service, name in (("LPV", "glab_lpv_2deg_60s"), ("LPV-200", "glab_lpv200_2deg_60s")):
        g = glab(f"{name}_avail.txt.gz")
        ours = smap.table.filter((pl.col("service") == service) & pl.col("hour").is_null()).sort("lat", "lon")
        assert np.array_equal(ours["lat"].to_numpy(), g[:, 0]) and np.array_equal(
            ours["lon"].to_numpy(), g[:, 1]
        )
        d = 100 * (ours["n_available"].to_numpy() - g[:, 3]) / g[:, 4]
        near, worst = np.mean(np.abs(d) <= 1), np.abs(d).max()
        print(
            f"{service}: {near:.2%} of nodes within 1 pp of gLAB, max {worst:.2f} pp, "
            f"same epoch count at {np.mean(d == 0):.1%}; mean difference {d.mean():+.3f} pp"
        )
    g = glab("glab_lpv_2deg_60s_iono.txt.gz")
    ours = smap.table.filter((pl.col("service") == "LPV") & pl.col("hour").is_null()).sort("lat", "lon")
    d = 100 * (ours["iono_availability"].to_numpy() - g[:, 3] / g[:, 4])
    print(
        f"ionosphere: {np.mean(np.abs(d) <= 1):.1%} of nodes within 1 pp, {np.mean(d == 0):.1%} equal, "
        f"max {np.abs(d).max():.1f} pp"
    )
    if client is not None:
        client.close()


if __name__ == "__main__":
    main()
