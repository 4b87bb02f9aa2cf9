"""SBAS message decoding, type by type, on real messages against gLAB's independent decoding of them.

Fixtures (tests/data/sbas, PROVENANCE.md there): real EGNOS PRN 123 hours 00-02 of 2019-01-14 and real MSAS
PRN 129/137 messages of 2008-05-26 (MT 28, MT 25 with velocity code 1, undecoded types 8/62/63), each with
gLAB v6's Pegasus conversion of the same messages (``glab/*.gz``). Types that no real set contains
(MT 0, 5, 24) are checked on messages encoded here bit by bit.
"""

from __future__ import annotations

import datetime as dt
import gzip
import re
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.ems import read_ems
from overbound.io.gpstime import leap_seconds
from overbound.io.sbas_crc import crc_ok, parity_of_data
from overbound.io.sbas_frames import SbasFrames
from overbound.sbas.igp import BAND_SIZES, band_igps
from overbound.sbas.messages import AI, SIGMA2_GIVE, SIGMA2_UDRE, decode

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
EGNOS_FILES = [DATA / "ems" / n for n in ("h00.ems.gz", "h01.ems", "h02.ems.gz")]
MSAS_FILE = DATA / "msas" / "ubx_20080526_sbas.ems.gz"
GPS_EPOCH_US = 315_964_800 * 1_000_000  # 1980-01-06 in microseconds since 1970-01-01
US = 1_000_000


@pytest.fixture(scope="module")
def egnos():
    frames, _ = read_ems(EGNOS_FILES)
    return frames, decode(frames)


@pytest.fixture(scope="module")
def msas():
    frames, _ = read_ems(MSAS_FILE)
    return frames, decode(frames)


# --- gLAB Pegasus files -------------------------------------------------------------------------------
def _text(name: str) -> str:
    return gzip.decompress((DATA / "glab" / name).read_bytes()).decode()


def peg(prefix: str, ext: str) -> pl.DataFrame:
    """A Pegasus table (all columns as strings) with ``time`` (the EMS tag) and ``geo``."""
    df = pl.read_csv((DATA / "glab" / f"{prefix}.{ext}.gz").read_bytes(), separator=";", infer_schema=False)
    tow = ((df["RX_TOM"].cast(pl.Float64) - 0.12).round(0)).cast(pl.Int64)
    us = GPS_EPOCH_US + (df["RX_WEEK"].cast(pl.Int64) * 604_800 + tow) * US
    return df.with_columns(time=us.cast(pl.Datetime("us")), geo=pl.col("PRN").cast(pl.Int16))


def close_to_printed(ours: np.ndarray | pl.Series, printed: pl.Series) -> None:
    """``ours`` equals gLAB's printed values within half a unit of their last printed digit."""
    ours = np.asarray(ours, dtype=float)
    text = printed.str.strip_chars().to_list()
    ref = np.array([float(s) for s in text])
    tol = np.array(
        [
            5e-7 * abs(v) if "E" in s.upper() else 0.5 * 10.0 ** -len(s.partition(".")[2])
            for s, v in zip(text, ref, strict=True)
        ]
    )
    bad = np.abs(ours - ref) > tol + 1e-15
    assert not bad.any(), (
        f"{int(bad.sum())} differ, first ours={ours[bad][0]!r} gLAB={text[np.argmax(bad)]!r}"
    )


def long_form(df: pl.DataFrame, stem: str, index: list[str], count: int, name: str) -> pl.DataFrame:
    """Pegasus columns ``<stem>01..`` (or ``<stem>1..``) as rows with their 1-based number ``k``."""
    cols = [c for c in df.columns if re.fullmatch(rf"{stem}\d+", c)][:count]
    out = df.unpivot(index=index, on=cols, variable_name="col", value_name=name)
    return out.with_columns(k=pl.col("col").str.slice(len(stem)).cast(pl.Int64)).drop("col")


def mask_bits(hexstr: str, n: int) -> list[int]:
    """1-based positions of the set bits among the first ``n`` bits of a hex string."""
    bits = "".join(f"{int(c, 16):04b}" for c in hexstr.strip('"'))
    return [i + 1 for i in range(n) if bits[i] == "1"]


# --- real messages, type by type --------------------------------------------------------------------
def test_every_real_message_is_decoded_or_counted(egnos, msas):
    for (frames, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        smt = peg(prefix, "smt")
        assert smt.height == len(frames)
        assert smt["CRC_PASS"].cast(pl.Int64).to_list() == frames.crc_ok.astype(int).tolist()
        assert smt["DMT"].cast(pl.Int64).to_list() == frames.mt.tolist()
        assert dec.counts["messages"] == len(frames) and dec.counts["bad_crc"] == 0
        assert dec.log["decoded"].sum() == dec.counts["decoded"]
    assert egnos[1].counts["not_decoded"] == {}
    gl = peg("msas", "smt")["DMT"].cast(pl.Int64)
    assert msas[1].counts["not_decoded"] == {m: int((gl == m).sum()) for m in (8, 62, 63)}


def test_mt1_prn_mask(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "s01")
        ours = dec.mask.group_by(["time", "geo"], maintain_order=True).agg("slot", pl.col("iodp").first())
        joined = ref.join(ours, on=["time", "geo"], how="full", coalesce=True)
        assert joined.height == ref.height == ours.height
        assert [mask_bits(h, 210) for h in joined["SVMASK"]] == joined["slot"].to_list()
        assert joined["IODP"].cast(pl.Int64).to_list() == joined["iodp"].to_list()
    first = egnos[1].mask.filter(pl.col("time") == egnos[1].mask["time"][0])
    assert first["position"].to_list() == list(range(1, first.height + 1))
    gps = first.filter(pl.col("system") == "GPS")
    assert gps["sv"].to_list() == gps["slot"].to_list()


def test_fast_corrections_mt2_to_4(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "sfc")
        idx = ["time", "geo", "TYPE", "IODF", "IODP"]
        prc = long_form(ref, "PRC", idx, 13, "PRC")
        udrei = long_form(ref, "UDREI", ["time", "geo"], 13, "UDREI")
        ref_long = prc.join(udrei, on=["time", "geo", "k"])
        ours = dec.fast.with_columns(k=((pl.col("position") - 1) % 13 + 1).cast(pl.Int64))
        j = ref_long.join(ours, on=["time", "geo", "k"], how="full", coalesce=True)
        assert j.height == ours.height == ref_long.height  # no MT 5 here: no position 52 to drop
        assert j["TYPE"].cast(pl.Int64).to_list() == j["mt"].cast(pl.Int64).to_list()
        assert (j["IODF"].cast(pl.Int64) == j["iodf"].cast(pl.Int64)).all()
        assert (j["IODP"].cast(pl.Int64) == j["iodp"].cast(pl.Int64)).all()
        close_to_printed(j["prc"], j["PRC"])
        assert (j["UDREI"].cast(pl.Int64) == j["udrei"].cast(pl.Int64)).all()
        assert (j["position"] == 13 * (j["mt"].cast(pl.Int16) - 2) + j["k"].cast(pl.Int16)).all()
    f = egnos[1].fast
    table = np.asarray(SIGMA2_UDRE)
    assert np.allclose(f["sigma2_udre"].to_numpy(), table[f["udrei"].to_numpy()], equal_nan=True)
    assert (
        f.filter(pl.col("udrei") >= 14)["sigma2_udre"].null_count() == f.filter(pl.col("udrei") >= 14).height
    )


def test_mt6_integrity(egnos):
    ref = peg("egnos_h00-02", "s06")
    udrei = long_form(ref, "UDREI", ["time", "geo", "IODF2", "IODF3", "IODF4", "IODF5"], 51, "UDREI")
    j = udrei.join(
        egnos[1].integrity.with_columns(k=pl.col("position").cast(pl.Int64)), on=["time", "geo", "k"]
    )
    assert j.height == udrei.height == egnos[1].integrity.height > 0
    assert (j["UDREI"].cast(pl.Int64) == j["udrei"].cast(pl.Int64)).all()
    block_iodf = np.choose(
        (j["k"].to_numpy() - 1) // 13, [j[f"IODF{b}"].cast(pl.Int64).to_numpy() for b in (2, 3, 4, 5)]
    )
    assert np.array_equal(block_iodf, j["iodf"].to_numpy())


def test_mt7_degradation_factors(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "s07")
        ai = long_form(ref, "AI", ["time", "geo", "TLAT", "IODP"], 51, "AI")
        j = ai.join(
            dec.fc_degradation.with_columns(k=pl.col("position").cast(pl.Int64)), on=["time", "geo", "k"]
        )
        assert j.height == ai.height == dec.fc_degradation.height > 0
        assert (j["AI"].cast(pl.Int64) == j["ai_index"].cast(pl.Int64)).all()
        assert (j["TLAT"].cast(pl.Float64) == j["tlat"]).all()
        assert (j["IODP"].cast(pl.Int64) == j["iodp"].cast(pl.Int64)).all()
    # a_i is increasing in the indicator, from 0 to 0.0058 m/s^2 (DO-229D Table A-7).
    assert AI[0] == 0.0 and AI[15] == 0.0058 and all(np.diff(AI) > 0)
    got = egnos[1].fc_degradation.select("ai_index", "ai").unique().sort("ai_index")
    assert got["ai"].to_list() == [AI[i] for i in got["ai_index"].to_list()]


def _rinex_h(prefix: str) -> pl.DataFrame:
    """MT 9 records of gLAB's RINEX-H files: t0, transmission time, and the state in km, km/s, km/s^2."""
    rows = []
    for path in sorted((DATA / "glab").glob(f"{prefix}_BRDC*H.gz")):
        lines = gzip.decompress(path.read_bytes()).decode().splitlines()
        body = lines[next(i for i, s in enumerate(lines) if "END OF HEADER" in s) + 1 :]
        for r in range(0, len(body) - 3, 4):
            rec = body[r : r + 4]
            nums = [
                [float(s[c : c + 19].replace("D", "E")) for c in range(start, len(s), 19)]
                for s, start in zip(rec, (22, 3, 3, 3), strict=True)
            ]
            yy, mo, dd, hh, mi = (int(x) for x in rec[0][3:17].split())
            t0 = dt.datetime(2000 + yy, mo, dd, hh, mi) + dt.timedelta(seconds=float(rec[0][17:22]))
            (af0, af1, tx), (x, vx, ax, _), (y, vy, ay, _), (z, vz, az, iodn) = nums
            tag = GPS_EPOCH_US + round(tx + 0.98) * US + _week_us(t0)
            rows.append(
                dict(
                    prn=100 + int(rec[0][:2]),
                    t0_ref=t0,
                    tag=tag,
                    af0=af0,
                    af1=af1,
                    iodn=iodn,
                    x=x,
                    y=y,
                    z=z,
                    vx=vx,
                    vy=vy,
                    vz=vz,
                    ax=ax,
                    ay=ay,
                    az=az,
                )
            )
    return pl.DataFrame(rows).with_columns(
        time=pl.col("tag").cast(pl.Datetime("us")), geo=pl.col("prn").cast(pl.Int16)
    )


def _week_us(t: dt.datetime) -> int:
    """Start of the GPS week of ``t`` since the GPS epoch, in microseconds."""
    return ((t - dt.datetime(1980, 1, 6)).days // 7) * 604_800 * US


def test_mt9_geo_navigation(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = _rinex_h(prefix)
        j = ref.join(dec.geo_nav, on=["time", "geo"])
        assert j.height == ref.height == dec.geo_nav.height > 0
        for c in ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az"):
            np.testing.assert_allclose(j[c] * 1000.0, j[f"{c}_right"], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(j["af0"], j["af0_right"], rtol=1e-9, atol=1e-20)
        np.testing.assert_allclose(j["af1"], j["af1_right"], rtol=1e-9, atol=1e-24)
        assert (j["iodn"] == j["iodn_right"].cast(pl.Float64)).all()
        assert j["t0_ref"].to_list() == j["t0"].to_list()
    # The first EGNOS MT 9 of the day applies at 23:59:44 of the day before: t0 is resolved backwards.
    first = egnos[1].geo_nav.row(0, named=True)
    assert first["t0_tod"] == 86_384 and first["t0"] == dt.datetime(2019, 1, 13, 23, 59, 44)


def test_mt10_degradation_parameters(egnos, msas):
    ours = (
        "brrc cltc_lsb cltc_v1 iltc_v1 cltc_v0 iltc_v0 cgeo_lsb cgeo_v igeo cer ciono_step iiono ciono_ramp "
        "rss_udre rss_iono ccovariance"
    ).split()
    names = {("CCOV" if c == "ccovariance" else c.upper()): c for c in ours}
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "s10")
        j = ref.join(dec.degradation, on=["time", "geo"])
        assert j.height == ref.height == dec.degradation.height > 0
        for theirs, ours in names.items():
            close_to_printed(j[ours].cast(pl.Float64), j[theirs])


def _bit_string(frames: SbasFrames, i: int) -> str:
    return "".join(f"{b:08b}" for b in frames.data[i].tolist())


def test_mt12_network_time_hand_decoded(egnos):
    """Bits of the first MT 12 sliced by hand at the DO-229 positions, and the content checked against the
    time tag: GPS time of week = tag - 1 s (the start of the transmission), GPS-UTC = 18 s in 2019."""
    frames, dec = egnos
    nt = dec.network_time
    i = int(np.flatnonzero(frames.mt == 12)[0])
    b = _bit_string(frames, i)
    u = lambda a, w: int(b[a : a + w], 2)  # noqa: E731
    s = lambda a, w: u(a, w) - (1 << w) * int(b[a])  # noqa: E731
    row = nt.row(0, named=True)
    assert row["a1"] == s(14, 24) * 2.0**-50 and row["a0"] == s(38, 32) * 2.0**-30
    assert row["t0t"] == u(70, 8) * 4096 and row["wnt"] == u(78, 8) and row["dt_ls"] == s(86, 8)
    assert (row["wn_lsf"], row["dn"], row["dt_lsf"], row["utc_id"]) == (
        u(94, 8),
        u(102, 8),
        s(110, 8),
        u(118, 3),
    )
    assert (row["gps_tow"], row["gps_week"]) == (u(121, 20), u(141, 10))

    tag_s = (nt["time"].dt.epoch("us").to_numpy() - GPS_EPOCH_US) // US
    assert np.array_equal(nt["gps_tow"].to_numpy(), tag_s % 604_800 - 1)
    assert (nt["gps_week"].to_numpy() == (tag_s // 604_800) % 1024).all()
    gps_utc = leap_seconds(nt["time"].dt.epoch("us").to_numpy())
    assert np.array_equal(nt["dt_ls"].to_numpy(), gps_utc)
    assert (np.abs(nt["a0"].to_numpy()) < 1e-6).all()


def _almanac(prefix: str) -> pl.DataFrame:
    rows = []
    for path in sorted((DATA / "glab").glob(f"{prefix}_GEO*.alm.gz")):
        for block in gzip.decompress(path.read_bytes()).decode().split("***"):
            kv = dict(re.findall(r"^(\w+)\s*:\s*(\S+)", block, re.M))
            if "RX_TOM" in kv:
                rows.append({k: float(v) for k, v in kv.items()})
    df = pl.DataFrame(rows)
    tow = (df["RX_TOM"] - 0.12).round(0).cast(pl.Int64)
    us = GPS_EPOCH_US + (df["RX_WEEK"].cast(pl.Int64) * 604_800 + tow) * US
    return df.with_columns(
        time=us.cast(pl.Datetime("us")),
        geo=pl.col("PRN").cast(pl.Int16),
        prn=pl.col("DATA_PRN").cast(pl.Int16),
    )


def test_mt17_geo_almanacs(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = _almanac(prefix)
        j = ref.join(dec.geo_almanac, on=["time", "geo", "prn"])
        assert j.height == ref.height == dec.geo_almanac.height > 0
        pairs = [("XGEO", "x"), ("YGEO", "y"), ("ZGEO", "z"), ("XGEO_RATE", "vx"), ("YGEO_RATE", "vy")]
        pairs += [("ZGEO_RATE", "vz"), ("DAYTIME_APPLICABILITY", "t0_tod"), ("DATA_ID", "data_id")]
        for theirs, ours in pairs:
            assert (j[theirs] == j[ours].cast(pl.Float64)).all(), theirs
        assert (j["HEALTH"] == (16 * j["provider"].cast(pl.Int64) + j["health"].cast(pl.Int64))).all()
    # EGNOS: provider 1 (EGNOS) for PRN 123 and 136.
    eg = egnos[1].geo_almanac
    assert set(eg["prn"].to_list()) == {123, 136} and eg["provider"].unique().to_list() == [1]


def test_mt18_igp_mask(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "s18")
        ours = dec.igp_mask.group_by(["time", "geo"], maintain_order=True).agg(
            "bit", pl.col("band").first(), pl.col("iodi").first(), pl.col("n_bands").first()
        )
        j = ref.join(ours, on=["time", "geo"], how="full", coalesce=True)
        assert j.height == ref.height == ours.height
        assert [mask_bits(h, 201) for h in j["IGP"]] == j["bit"].to_list()
        for theirs, col in (("BN", "band"), ("IODI", "iodi"), ("NB", "n_bands")):
            assert (j[theirs].cast(pl.Int64) == j[col].cast(pl.Int64)).all()
    m = egnos[1].igp_mask
    assert m.filter(pl.col("lat").is_null()).height == 0
    assert m.group_by("time").agg(ok=(pl.col("igp") == pl.int_range(1, pl.len() + 1)).all())["ok"].all()
    # Spot check against the band rule: band 4 starts at 20 W, the 16th bit of its first meridian is 10 N.
    row = m.filter((pl.col("band") == 4) & (pl.col("bit") == 16)).row(0, named=True)
    assert (row["lat"], row["lon"]) == (10.0, -20.0)


def test_igp_band_geometry():
    assert BAND_SIZES == (201,) * 8 + (200, 192, 192)
    pts = [tuple(p) for b in range(9) for p in zip(*band_igps(b), strict=True)]
    assert len(pts) == len(set(pts)) == 1808
    north85 = sorted(lon for lat, lon in pts if lat == 85)
    south85 = sorted(lon for lat, lon in pts if lat == -85)
    assert north85 == [-180, -90, 0, 90] and south85 == [-140, -50, 40, 130]
    for b, sign in ((9, 1), (10, -1)):
        lat, lon = band_igps(b)
        assert set(np.unique(lat * sign).tolist()) == {60, 65, 70, 75, 85}
        assert np.all(np.diff(lon[lat == sign * 60]) == 5) and (lat * sign >= 60).all()
    assert band_igps(10)[1][-12:].tolist() == list(range(-170, 190, 30))


def test_mt26_ionospheric_delays(egnos, msas):
    for (_, dec), prefix in ((egnos, "egnos_h00-02"), (msas, "msas")):
        ref = peg(prefix, "s26")
        delay = long_form(ref, "DELAY", ["time", "geo", "BN", "BI", "IODI"], 15, "DELAY")
        givei = long_form(ref, "GIVEI", ["time", "geo"], 15, "GIVEI")
        r = delay.join(givei, on=["time", "geo", "k"])
        ours = dec.iono.with_columns(k=((pl.col("igp") - 1) % 15 + 1).cast(pl.Int64))
        j = r.join(ours, on=["time", "geo", "k"], how="full", coalesce=True)
        assert j.height == r.height == ours.height > 0
        close_to_printed(j["givd"], j["DELAY"])
        for theirs, col in (("GIVEI", "givei"), ("BN", "band"), ("BI", "block"), ("IODI", "iodi")):
            assert (j[theirs].cast(pl.Int64) == j[col].cast(pl.Int64)).all()
    io = egnos[1].iono
    assert np.allclose(
        io["sigma2_give"].to_numpy(), np.asarray(SIGMA2_GIVE)[io["givei"].to_numpy()], equal_nan=True
    )
    assert (
        io.filter(pl.col("givei") == 15)["sigma2_give"].null_count()
        == io.filter(pl.col("givei") == 15).height
    )
    assert (io["givd_dnu"] == (io["givd"] == 63.875)).all()


def test_mt27_service_message(egnos):
    ref = peg("egnos_h00-02", "s27")
    dec = egnos[1]
    j = ref.join(dec.service, on=["time", "geo"])
    assert j.height == ref.height == dec.service.height > 0
    pairs = [("IODS", "iods"), ("NS", "n_messages"), ("MSG", "message_number"), ("NR", "n_regions")]
    pairs += [("PC", "priority"), ("DELTAI", "dudrei_in"), ("DELTAO", "dudrei_out")]
    for theirs, col in pairs:
        assert (j[theirs].cast(pl.Int64) == j[col].cast(pl.Int64)).all(), theirs
    regions = dec.service_regions
    for r in range(1, 6):
        jr = ref.join(regions.filter(pl.col("region") == r), on=["time", "geo"])
        assert jr.height == (ref[f"RS{r}"].is_not_null() & (ref["NR"].cast(pl.Int64) >= r)).sum()
        pairs = [(f"LAT1{r}", "lat1"), (f"LON1{r}", "lon1"), (f"LAT2{r}", "lat2"), (f"LON2{r}", "lon2")]
        for theirs, col in [*pairs, (f"RS{r}", "square")]:
            assert (jr[theirs].cast(pl.Int64) == jr[col].cast(pl.Int64)).all()
    assert regions.height == dec.service["n_regions"].cast(pl.Int64).sum()


def _ssc(prefix: str) -> pl.DataFrame:
    ref = peg(prefix, "ssc")
    parts = []
    for s in range(1, 5):
        names = "VC MASK IOD DX DY DZ DAF0 DXROC DYROC DZROC DAF1 TOA IODP".split()
        cols = {f"{c}{s}": c for c in names}
        parts.append(ref.select("time", "geo", *cols).rename(cols))
    return pl.concat(parts).filter(pl.col("MASK").cast(pl.Int64) > 0)


def test_mt25_long_term_both_velocity_codes(egnos, msas):
    for (_, dec), prefix, vc in ((egnos, "egnos_h00-02", 0), (msas, "msas", 1)):
        keys = ["time", "geo", "position", "iode", "dx"]
        ref = (
            _ssc(prefix)
            .with_columns(
                position=pl.col("MASK").cast(pl.Int16),
                iode=pl.col("IOD").cast(pl.Int16),
                dx=pl.col("DX").cast(pl.Float64),
            )
            .sort(keys)
        )
        ours = dec.long_term.sort(keys)
        assert ref.height == ours.height > 0 and ours["velocity_code"].unique().to_list() == [vc]
        assert ref.select(keys).equals(ours.select(keys))
        for theirs, col in (
            ("DY", "dy"),
            ("DZ", "dz"),
            ("DAF0", "daf0"),
            ("DXROC", "ddx"),
            ("DYROC", "ddy"),
            ("DZROC", "ddz"),
            ("DAF1", "daf1"),
        ):
            close_to_printed(ours[col], ref[theirs])
        assert (ref["IODP"].cast(pl.Int64) == ours["iodp"].cast(pl.Int64)).all()
        assert (ref["VC"].cast(pl.Int64) == ours["velocity_code"].cast(pl.Int64)).all()
        if vc == 1:
            assert (ref["TOA"].cast(pl.Float64) == ours["t0_tod"]).all()
            lag = (ours["t0"] - ours["time"]).dt.total_seconds()
            assert (lag.abs() <= 43_200).all()
        else:
            assert ours["t0"].null_count() == ours.height and (ours["ddx"] == 0).all()


def test_mt28_covariance(msas):
    ref = peg("msas", "s28")
    dec = msas[1]
    parts = []
    for s in (1, 2):
        entries = {
            f"E{ij}{s}": f"E{ij}" for ij in ("11", "22", "33", "44", "12", "13", "14", "23", "24", "34")
        }
        names = {f"MASK{s}": "MASK", f"SE{s}": "SE"} | entries
        parts.append(ref.select("time", "geo", "IODP", *names).rename(names))
    r = (
        pl.concat(parts)
        .filter(pl.col("MASK").cast(pl.Int64) > 0)
        .with_columns(position=pl.col("MASK").cast(pl.Int16))
    )
    j = r.join(dec.covariance, on=["time", "geo", "position"])
    assert j.height == r.height == dec.covariance.height > 0
    scale = 2.0 ** (j["SE"].cast(pl.Float64) - 5)
    for ij in ("11", "22", "33", "44", "12", "13", "14", "23", "24", "34"):
        assert (j[f"r{ij}"] == scale * j[f"E{ij}"].cast(pl.Float64)).all(), ij
    assert (j["IODP"].cast(pl.Int64) == j["iodp"].cast(pl.Int64)).all()
    # R is the Cholesky factor: its diagonal is non-negative, so C = R^T R has a positive diagonal.
    assert (j.select("r11", "r22", "r33", "r44").to_numpy() >= 0).all()


def test_bad_crc_messages_are_dropped_and_counted(egnos):
    frames, clean = egnos
    data = frames.data.copy()
    hit = np.flatnonzero(np.isin(frames.mt, (1, 26)))[:5]
    data[hit, 20] ^= 0x04
    damaged = SbasFrames(frames.time, frames.prn, data, crc_ok(data), frames.file, frames.line, frames.files)
    dec = decode(damaged)
    assert dec.counts["bad_crc"] == 5 and dec.counts["decoded"] == clean.counts["decoded"] - 5
    assert dec.log.filter(~pl.col("crc_ok"))["time"].to_list() == [
        dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=int(t)) for t in frames.time[hit]
    ]
    gone = set(frames.time[hit].tolist())
    assert not gone & set(dec.mask["time"].dt.epoch("us").to_list())
    assert not gone & set(dec.iono["time"].dt.epoch("us").to_list())
    assert dec.iono.height == clean.iono.height - 15 * int((frames.mt[hit] == 26).sum())


# --- constructed messages for the types absent from the real data ------------------------------------
def encode(mt: int, fields: list[tuple[int, int, int]], preamble: int = 0x53) -> np.ndarray:
    """A 32-byte message with the given (first bit, width, integer value) fields and a valid CRC."""
    bits = ["0"] * 256

    def put(start: int, width: int, value: int) -> None:
        bits[start : start + width] = f"{value & ((1 << width) - 1):0{width}b}"

    put(0, 8, preamble)
    put(8, 6, mt)
    for start, width, value in fields:
        put(start, width, value)
    put(226, 24, int(parity_of_data(_frame(bits)[None, :])[0]))  # test_crc checks it by bit division
    return _frame(bits)


def _frame(bits: list[str]) -> np.ndarray:
    return np.frombuffer(int("".join(bits), 2).to_bytes(32, "big"), np.uint8)


def frames_of(messages: list[np.ndarray], start: dt.datetime) -> SbasFrames:
    data = np.vstack(messages)
    t0 = (start - dt.datetime(1970, 1, 1)) // dt.timedelta(microseconds=1)
    n = len(messages)
    return SbasFrames(
        time=t0 + US * np.arange(n, dtype=np.int64),
        prn=np.full(n, 123, np.int16),
        data=data,
        crc_ok=crc_ok(data),
        file=np.zeros(n, np.int16),
        line=np.arange(1, n + 1),
    )


def test_mt24_mixed_fast_and_long_term_velocity_code_1():
    """DO-229 MT 24: six 12-bit PRCs (0.125 m) from bit 14, six UDREIs from bit 86, IODP at 110, fast block ID
    at 112, IODF at 114, then the second half of an MT 25 at bit 120 (here velocity code 1)."""
    prc_m = [-12.375, 0.0, 3.125, 255.875, -256.0, 1.5]
    udrei = [0, 5, 11, 13, 14, 15]
    fields = [(14 + 12 * i, 12, round(v / 0.125)) for i, v in enumerate(prc_m)]
    fields += [(86 + 4 * i, 4, u) for i, u in enumerate(udrei)] + [(110, 2, 3), (112, 2, 1), (114, 2, 2)]
    # Half message (velocity code 1): PRN mask number 7, IODE 99, dx -2.5 m, dy 10.125 m, dz 0.375 m,
    # daf0 -3 * 2^-31 s, rates 2^-11 * (5, -7, 127) m/s, daf1 -2 * 2^-39 s/s, t0 = 1 * 16 s of day, IODP 3.
    fields += [(120, 1, 1), (121, 6, 7), (127, 8, 99), (135, 11, -20), (146, 11, 81), (157, 11, 3)]
    fields += [
        (168, 11, -3),
        (179, 8, 5),
        (187, 8, -7),
        (195, 8, 127),
        (203, 8, -2),
        (211, 13, 1),
        (224, 2, 3),
    ]
    dec = decode(frames_of([encode(24, fields)], dt.datetime(2019, 1, 14, 23, 59, 50)))
    fast = dec.fast
    assert fast["position"].to_list() == [14, 15, 16, 17, 18, 19]  # block 1 = positions 14-26
    assert fast["prc"].to_list() == prc_m and fast["udrei"].to_list() == udrei
    assert fast["iodp"].unique().to_list() == [3] and fast["iodf"].unique().to_list() == [2]
    assert fast["mt"].unique().to_list() == [24]
    lt = dec.long_term.row(0, named=True)
    assert dec.long_term.height == 1
    assert (lt["mt"], lt["half"], lt["velocity_code"], lt["position"], lt["iode"], lt["iodp"]) == (
        24,
        1,
        1,
        7,
        99,
        3,
    )
    assert (lt["dx"], lt["dy"], lt["dz"]) == (-2.5, 10.125, 0.375)
    assert lt["daf0"] == -3 * 2.0**-31 and lt["daf1"] == -2 * 2.0**-39
    assert (lt["ddx"], lt["ddy"], lt["ddz"]) == (5 * 2.0**-11, -7 * 2.0**-11, 127 * 2.0**-11)
    # t0 = 16 s of day, 26 s after a message sent at 23:59:50: it is the next day.
    assert lt["t0_tod"] == 16 and lt["t0"] == dt.datetime(2019, 1, 15, 0, 0, 16)


def test_mt5_last_block_has_twelve_positions():
    fields = [(14, 2, 1), (16, 2, 2)] + [(18 + 12 * i, 12, i - 6) for i in range(13)]
    fields += [(174 + 4 * i, 4, i) for i in range(13)]
    fast = decode(frames_of([encode(5, fields)], dt.datetime(2019, 1, 14))).fast
    assert fast["position"].to_list() == list(range(40, 52))  # 52 would be past the 51-satellite mask
    assert fast["prc"].to_list() == [0.125 * (i - 6) for i in range(12)]
    assert fast["udrei"].to_list() == list(range(12)) and fast["iodf"].unique().to_list() == [1]


def test_mt0_plain_and_test_mode():
    zero = encode(0, [])
    as_mt2 = encode(
        0,
        [(14, 2, 1), (16, 2, 0)]
        + [(18 + 12 * i, 12, 8 * i) for i in range(13)]
        + [(174 + 4 * i, 4, 3) for i in range(13)],
    )
    frames = frames_of([zero, as_mt2], dt.datetime(2019, 1, 14))
    plain = decode(frames)
    assert plain.dont_use["all_zero"].to_list() == [True, False]
    assert plain.fast.height == 0 and plain.counts["by_type"] == {0: 2}
    test_mode = decode(frames, mt0_as_mt2=True)
    assert test_mode.fast["position"].to_list() == list(range(1, 14))
    assert test_mode.fast["prc"].to_list() == [float(i) for i in range(13)]
    assert test_mode.fast["mt"].unique().to_list() == [0]
    assert test_mode.fast["time"].unique().to_list() == [dt.datetime(2019, 1, 14, 0, 0, 1)]


def test_tables_are_time_ordered_and_decoding_is_repeatable(egnos):
    frames, dec = egnos
    again = decode(frames)
    for name, table in dec.tables().items():
        assert table["time"].is_sorted(), name
        assert table.equals(again.tables()[name]), name
