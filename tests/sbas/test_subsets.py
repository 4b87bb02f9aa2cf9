"""Stanford-ESA all-subsets histogram (issue 6 item 5) on the engine's synthetic Toulouse fixture."""

from __future__ import annotations

import functools
import itertools
import math
from pathlib import Path

import matplotlib
import numpy as np
import polars as pl
import pytest

from overbound.io.ems import read_ems
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.methods.counting import plot_max, stanford_counts, stanford_histogram
from overbound.sbas.engine import run_sbas
from overbound.sbas.messages import decode
from overbound.sbas.solution import K_H_PA, K_V_PA
from overbound.sbas.subsets import (
    all_subsets,
    all_subsets_by_service,
    subset_count,
    subset_masks,
    subset_solutions,
)

matplotlib.use("Agg")

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"
_AXES = ("horizontal", "vertical")


@functools.cache
def _run():
    obs, _ = read_rinex_obs(FIX / "SYNT0140_h02-04.19o.gz")
    frames, _ = read_ems([DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"])
    nav, _ = read_rinex_nav(FIX / "brdc0140.19n.gz")
    return run_sbas(obs.table, nav.table, decode(frames), obs.header.approx_position)


def _some_epochs(every: int) -> pl.DataFrame:
    sats = _run().satellites
    times = sats.filter(pl.col("used"))["time"].unique().sort()
    return sats.filter(pl.col("time").is_in(times.gather_every(every).implode()))


def test_full_set_reproduces_run_sbas():
    sats = _some_epochs(15)
    sol = subset_solutions(sats).filter(pl.col("subset") == 0)
    ref = _run().epochs.join(sol, on="time", how="inner")
    assert ref.height == sats.filter(pl.col("used"))["time"].n_unique() > 10
    assert (ref["size"] == ref["nsv"].cast(pl.Int64)).all()
    for col in ("hpe", "vpe", "hpl", "vpl"):
        np.testing.assert_allclose(ref[f"{col}_right"], ref[col], rtol=0, atol=1e-9)


def test_counts_are_binomial_sums():
    sats = _run().satellites
    nsv = _run().epochs.filter(pl.col("nsv") >= 4)["nsv"].to_numpy().astype(int)
    res = all_subsets(sats, max_size=7)
    assert res.n_epochs == nsv.size
    assert res.n_subsets + res.n_singular == sum(subset_count(int(n), 4, 7) for n in nsv)
    assert res.by_size == {k: sum(math.comb(int(n), k) for n in nsv) for k in range(4, 8)}
    for axis in ("horizontal", "vertical"):
        assert res.counts[axis].total == res.n_subsets
        assert getattr(res, axis).counts.sum() == res.n_subsets  # clipped ones sit in the border bins
    assert subset_count(10) == 848 == subset_masks(10).shape[0]
    assert subset_masks(6, 4, 5).sum(axis=1).tolist() == [5] * 6 + [4] * 15


def test_against_brute_force_loop():
    sats = _some_epochs(60)
    ours = subset_solutions(sats, max_size=8)
    rows = []
    for (t,), g in sats.filter(pl.col("used")).sort("prn").group_by("time", maintain_order=True):
        e, a = np.deg2rad(g["elevation"].to_numpy()), np.deg2rad(g["azimuth"].to_numpy())
        geo = np.column_stack([-np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a), -np.sin(e), np.ones(e.size)])
        w, y, prn = 1 / g["sigma"].to_numpy() ** 2, g["prefit"].to_numpy(), g["prn"].to_numpy()
        for k in range(min(8, e.size), 3, -1):
            for c in map(list, itertools.combinations(range(e.size), k)):
                cov = np.linalg.inv(geo[c].T @ np.diag(w[c]) @ geo[c])
                x = cov @ geo[c].T @ (w[c] * y[c])
                d_major = np.sqrt((cov[0, 0] + cov[1, 1]) / 2
                                  + np.sqrt(((cov[0, 0] - cov[1, 1]) / 2) ** 2 + cov[0, 1] ** 2))  # fmt: skip
                rows.append((t, " ".join(map(str, prn[c])), np.hypot(x[0], x[1]), x[2], K_H_PA * d_major,
                             K_V_PA * np.sqrt(cov[2, 2])))  # fmt: skip
    brute = pl.DataFrame(rows, schema=["time", "prns", "hpe", "vpe", "hpl", "vpl"], orient="row")
    joined = ours.join(brute, on=("time", "prns"), how="full", coalesce=True)
    assert joined.height == brute.height == ours.height > 500
    for col in ("hpe", "vpe", "hpl", "vpl"):
        # rtol 1e-7: a few subsets are nearly singular (PL of hundreds of metres, condition ~1e8)
        np.testing.assert_allclose(joined[col], joined[f"{col}_right"], rtol=1e-7, atol=1e-9)
    # the histogram is the counting module's histogram of exactly these values
    res = all_subsets(sats, max_size=8)
    ref = stanford_histogram(ours["vpe"], ours["vpl"], axis="vertical", max_value=80.0)
    np.testing.assert_array_equal(res.vertical.counts, ref.counts)
    assert res.counts["horizontal"] == stanford_counts(ours["hpe"].to_numpy(), ours["hpl"].to_numpy(), 40.0)
    assert res.worst_ratio["vertical"] == pytest.approx((ours["vpe"].abs() / ours["vpl"]).max(), rel=1e-12)


def test_one_pass_serves_several_alert_limits_exactly():
    sats = _some_epochs(10)
    limits = {"LPV-200": (40.0, 35.0), "APV-II": (40.0, 20.0), "NPA": (556.0, None)}
    multi = all_subsets_by_service(sats, limits, max_size=6)
    assert list(multi) == list(limits)
    sol = subset_solutions(sats, max_size=6).filter(pl.col("hpl").is_not_nan())
    for name, (hal, val) in limits.items():
        one, got = all_subsets(sats, horizontal_al=hal, vertical_al=val, max_size=6), multi[name]
        assert got.alert_limits == one.alert_limits == {"horizontal": hal, "vertical": val}
        assert got.counts == one.counts and set(got.counts) == ({"horizontal"} if val is None else set(_AXES))
        for f in ("n_epochs", "n_subsets", "n_singular", "by_size", "worst_ratio"):
            assert getattr(got, f) == getattr(one, f), f
        for axis, al in zip(_AXES, (hal, val), strict=True):
            h, ref = getattr(got, axis), getattr(one, axis)
            if al is None:
                assert h is None and ref is None
                continue
            np.testing.assert_array_equal(h.counts, ref.counts)
            np.testing.assert_array_equal(h.edges, ref.edges)
            assert h.clipped == ref.clipped
            # and each service's histogram and counts are the counting module's on its own range
            pe, pl_ = sol[axis[0] + "pe"].to_numpy(), sol[axis[0] + "pl"].to_numpy()
            direct = stanford_histogram(pe, pl_, axis=axis, max_value=plot_max(al))
            np.testing.assert_array_equal(h.counts, direct.counts)
            assert h.clipped == direct.clipped and got.counts[axis] == stanford_counts(np.abs(pe), pl_, al)
    assert multi["NPA"].horizontal.edges[-1] == plot_max(556.0) > multi["APV-II"].horizontal.edges[-1]


def test_singular_subsets_are_counted_and_left_out():
    # satellites 1 and 2 share a line of sight: the 3 four-satellite subsets holding both are singular
    el, az = [30.0, 30.0, 30.0, 60.0, 80.0], [0.0, 0.0, 120.0, 240.0, 45.0]
    sats = pl.DataFrame(
        {
            "time": [0] * 5,
            "prn": [1, 2, 3, 4, 5],
            "used": [True] * 5,
            "elevation": el,
            "azimuth": az,
            "sigma": [1.0] * 5,
            "prefit": [0.1, -0.2, 0.3, 0.0, 0.5],
        }
    )
    res = all_subsets(sats)
    assert (res.n_subsets, res.n_singular) == (3, 3)
    sol = subset_solutions(sats)
    assert sol.filter(pl.col("hpl").is_nan())["prns"].to_list() == ["1 2 3 4", "1 2 3 5", "1 2 4 5"]


def test_bad_input_and_drawing():
    sats = _some_epochs(60)
    with pytest.raises(ValueError, match="lacks"):
        all_subsets(sats.drop("prefit"))
    with pytest.raises(ValueError, match="at least 4"):
        all_subsets(sats, min_size=3)
    with pytest.raises(ValueError, match="mode"):
        all_subsets(sats, mode="CAT")
    with pytest.raises(ValueError, match="no alert limits"):
        all_subsets_by_service(sats, {})
    with pytest.raises(ValueError, match="positive"):
        all_subsets(sats, horizontal_al=0.0)
    with pytest.raises(ValueError, match="not a"):
        all_subsets_by_service(sats, {"LPV": 40.0})  # type: ignore[dict-item]
    from overbound.report.figures import plot_stanford

    res = all_subsets(sats, max_size=6)
    ax = plot_stanford(
        res.vertical, res.counts["vertical"], alert_limit=50.0, service="APV-I (all subsets)", unit="subsets"
    )
    assert any(a.get_gid() == "alert-limit-pe" for a in ax.get_children())
    assert any(a.get_ylabel() == "subsets per bin" for a in ax.figure.axes)  # the colour bar
    note = next(a for a in ax.get_children() if a.get_gid() == "stanford-note")
    assert " subsets, AL 50 m" in note.get_text()
