"""RINEX observation reader: real file cuts (tests/data/rinex, see PROVENANCE.md there) and damaged copies."""

from __future__ import annotations

import datetime as dt
import gzip
import math
from pathlib import Path

import hatanaka
import numpy as np
import polars as pl
import pytest

from overbound.io.gpstime import PLAUSIBLE_END
from overbound.io.rinex_obs import RINEX2_CODES, RinexObs, read_rinex_obs
from overbound.io.schema import InputError, ReadReport

DATA = Path(__file__).resolve().parents[1] / "data" / "rinex"
SYNT = DATA / "SYNT0140_cut.19o.gz"  # RINEX 2.11, GPS, C1 L1 S1, 13-14 satellites
ESBC = DATA / "ESBC00DNK_cut.crx.gz"  # RINEX 3.05 mixed, Hatanaka + gzip
ESBC_V2 = DATA / "ESBC00DNK_cut_v211.20o.gz"  # the same epochs as RINEX 2.11, 9 types


def _text(path: Path) -> str:
    raw = path.read_bytes()
    raw = gzip.decompress(raw) if raw[:2] == b"\x1f\x8b" else raw
    return (hatanaka.decompress(raw) if b"COMPACT RINEX" in raw[:80] else raw).decode()


def _write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _field(text: str) -> tuple[float, int, int]:
    text = text.ljust(16)
    value = float(text[:14]) if text[:14].strip() else math.nan
    return value, int(text[14]) if text[14] != " " else 0, int(text[15]) if text[15] != " " else 0


def _slow_read(path: Path) -> tuple[list[tuple[dt.datetime, str, dict]], dict[str, list[str]]]:
    """Independent line-by-line reading: (time, satellite, {file code: (value, lli, ssi)}) per record."""
    lines = _text(path).splitlines()
    v3 = float(lines[0][:9]) >= 3
    types: dict[str, list[str]] = {}
    i, cur = 1, None
    while "END OF HEADER" not in lines[i]:
        if "# / TYPES OF OBSERV" in lines[i]:
            types.setdefault("*", []).extend(lines[i][6:60].split())
        if "SYS / # / OBS TYPES" in lines[i]:
            cur = lines[i][0] if lines[i][0] != " " else cur
            types.setdefault(cur, []).extend(lines[i][7:60].split())
        i += 1
    i += 1
    out = []
    while i < len(lines):
        e = lines[i]
        if v3:
            t = dt.datetime(int(e[2:6]), int(e[7:9]), int(e[10:12]), int(e[13:15]), int(e[16:18]))
            t += dt.timedelta(seconds=float(e[18:29]))
            n = int(e[32:35])
            for s in lines[i + 1 : i + 1 + n]:
                obs = {c: _field(s[3 + 16 * m : 19 + 16 * m]) for m, c in enumerate(types[s[0]])}
                out.append((t, f"{s[0]}{int(s[1:3]):02d}", obs))
            i += 1 + n
            continue
        t = dt.datetime(2000 + int(e[1:3]), int(e[4:6]), int(e[7:9]), int(e[10:12]), int(e[13:15]))
        t += dt.timedelta(seconds=float(e[15:26]))
        n = int(e[29:32])
        head = -(-n // 12)
        ids = "".join(lines[i + k].ljust(68)[32:68] for k in range(head))
        per = -(-len(types["*"]) // 5)
        i += head
        for j in range(n):
            rec = "".join(lines[i + r].ljust(80) for r in range(per))
            i += per
            obs = {c: _field(rec[16 * m : 16 * m + 16]) for m, c in enumerate(types["*"])}
            out.append((t, ids[3 * j] + f"{int(ids[3 * j + 1 : 3 * j + 3]):02d}", obs))
    return out, types


def _assert_same(path: Path) -> pl.DataFrame:
    rows, types = _slow_read(path)
    obs, report = read_rinex_obs(path)
    t = obs.table
    assert t.height == len(rows) == report.rows_kept == report.rows_read
    assert t["time"].to_list() == [r[0] for r in rows]
    assert t["sat"].to_list() == [r[1] for r in rows]
    for k, (_, sat, fields) in enumerate(rows):
        for code, (value, lli, ssi) in fields.items():
            name = RINEX2_CODES[sat[0]].get(code) if "*" in types else code
            if name is None:  # a RINEX 2 type this system does not have (P1 of SBAS): blank
                assert math.isnan(value)
                continue
            got = t[name][k]
            assert got == value or (math.isnan(got) and math.isnan(value)), (k, sat, code)
            assert (t[f"{name}_lli"][k], t[f"{name}_ssi"][k]) == (lli, ssi), (k, sat, code)
    return t


def test_rinex2_reads_like_line_by_line_with_continuation_lines():
    t = _assert_same(SYNT)
    counts = t.group_by("time").len()["len"]
    assert counts.min() > 12 and counts.n_unique() > 1  # every epoch line continues past 12 satellites


def test_rinex3_hatanaka_mixed_reads_like_line_by_line():
    t = _assert_same(ESBC)
    assert set(t["system"].unique()) == {"C", "E", "G", "R", "S"}
    gps = t.filter(pl.col("system") == "G")
    assert gps["S1C"].is_nan().sum() == 0 and gps["C1W"].is_nan().sum() > 0  # blank fields are NaN
    assert t.filter(pl.col("system") == "C")["C1C"].is_nan().all()  # not a BeiDou type here
    assert (t["L1C_lli"] > 0).sum() + (t["L1C_ssi"] > 0).sum() > 0


def test_rinex2_with_nine_types_reads_like_line_by_line():
    _assert_same(ESBC_V2)


def test_rinex2_codes_map_to_the_rinex3_ones():
    """The RINEX 2.11 rewrite holds the RINEX 3 values under C1/P1/L1/D1/S1/P2/L2/D2/S2."""
    v2, _ = read_rinex_obs(ESBC_V2)
    v3, _ = read_rinex_obs(ESBC, systems="GRS")
    cols = [c for c in v2.codes]
    assert set(cols) == {
        "C1C",
        "C1W",
        "L1C",
        "D1C",
        "S1C",
        "C2W",
        "L2W",
        "D2W",
        "S2W",
        "C1P",
        "C2P",
        "L2P",
    } | {
        "D2P",
        "S2P",
    }
    joined = v2.table.join(v3.table, on=["time", "sat"], how="inner", suffix="_v3")
    assert joined.height == v2.table.height == v3.table.height
    for c in cols:
        for suffix in ("", "_lli", "_ssi"):
            a, b = joined[c + suffix].to_numpy(), joined[c + suffix + "_v3"].to_numpy()
            assert np.array_equal(a, b, equal_nan=True), c + suffix


def test_plain_gzip_and_hatanaka_give_the_same_table(tmp_path):
    text = _text(ESBC)
    plain = tmp_path / "esbc.rnx"
    plain.write_text(text)
    gz = tmp_path / "esbc.rnx.gz"
    gz.write_bytes(gzip.compress(text.encode()))
    crlf = tmp_path / "esbc_crlf.rnx"
    crlf.write_bytes(text.replace("\n", "\r\n").encode())
    ref, _ = read_rinex_obs(ESBC)
    for path in (plain, gz, crlf):
        other, _ = read_rinex_obs(path)
        assert other.table.equals(ref.table)


def test_satellite_identifiers_with_blanks(tmp_path):
    """RINEX 2 allows " 7" (system of the file) and writers emit "G 7"; both mean G07."""
    lines = _text(SYNT).splitlines()
    body = next(k for k, s in enumerate(lines) if "END OF HEADER" in s) + 1
    epoch = lines[body]
    assert epoch[32:35] == "G01" and epoch[35:38] == "G07"
    lines[body] = epoch[:32] + "  1" + "G 7" + epoch[38:]
    obs, report = read_rinex_obs(_write(tmp_path, "blank_ids.19o", lines))
    ref, _ = read_rinex_obs(SYNT)
    assert obs.table.equals(ref.table) and report.n_rejected == 0


def test_header_fields():
    obs, _ = read_rinex_obs(ESBC)
    h = obs.header
    assert h.version == 3.05 and h.system == "M" and h.marker_name == "ESBC00DNK"
    assert h.approx_position == (3582105.2910, 532589.7313, 5232754.8054)
    assert h.antenna_delta_hen == (0.2160, 0.0, 0.0)
    assert h.receiver_type == "SEPT POLARX5" and h.antenna_type == "ASH701945E_M    SCIS"
    assert h.interval == 30.0 and h.time_system == "GPS"
    assert h.time_of_first_obs == int(dt.datetime(2020, 6, 25).replace(tzinfo=dt.UTC).timestamp()) * 1_000_000
    assert h.glonass_slots[2] == -4 and len(h.glonass_slots) == 23
    assert h.codes["S"] == ("C1C", "C5I", "D1C", "D5I", "L1C", "L5I", "S1C", "S5I")
    v2, _ = read_rinex_obs(SYNT)
    assert v2.header.obs_types == {"G": ("C1", "L1", "S1")} and v2.header.codes == {
        "G": ("C1C", "L1C", "S1C")
    }
    assert v2.table["time"][0] == dt.datetime(2019, 1, 14, 1, 50)


def test_epochs_table_and_glonass_time_system(tmp_path):
    obs, _ = read_rinex_obs(SYNT)
    assert obs.epochs.height == 20 and obs.epochs["nsat"].sum() == obs.table.height
    lines = _text(SYNT).splitlines()
    i = next(k for k, s in enumerate(lines) if "TIME OF FIRST OBS" in s)
    lines[i] = lines[i][:48] + "GLO" + lines[i][51:]  # epochs in UTC: the table adds GPS-UTC (18 s in 2019)
    glo, _ = read_rinex_obs(_write(tmp_path, "glo.19o", lines))
    assert (glo.table["time"] - obs.table["time"]).unique().to_list() == [dt.timedelta(seconds=18)]


def test_epoch_flags_power_failure_events_and_cycle_slips(tmp_path):
    lines = _text(SYNT).splitlines()
    body = next(k for k, s in enumerate(lines) if "END OF HEADER" in s) + 1
    epochs = [k for k in range(body, len(lines)) if lines[k][18:19] == "." and lines[k][28] in "0123456"]
    second, third = epochs[1], epochs[2]
    lines[second] = lines[second][:28] + "1" + lines[second][29:]  # power failure before this epoch
    sats = lines[third][32:38]
    slip = [lines[third][:28] + "6  2" + sats, lines[third + 2], lines[third + 3]]  # cycle-slip records
    event = [
        lines[third][:28] + "4  2",
        f"{'SECOND HEADER COMMENT':60}COMMENT",
        f"{'  4627851.2711   119640.7753  4372993.8468':60}APPROX POSITION XYZ",
    ]
    external = [f"{'':28}5  0"]  # RINEX 2: an event's date may be blank
    lines[third:third] = event + slip + external
    obs, report = read_rinex_obs(_write(tmp_path, "flags.19o", lines))
    ref, _ = read_rinex_obs(SYNT)
    assert obs.table.drop("flag").equals(ref.table.drop("flag"))  # events add no observations
    flagged = obs.table.filter(pl.col("flag") == 1)["time"].unique().to_list()
    assert flagged == [ref.epochs["time"][1]]
    ev = obs.events
    assert ev["flag"].to_list() == [4, 6, 5]
    assert ev["records"].to_list() == [2, 2, 0]
    assert ev["text"][0].splitlines()[0].startswith("SECOND HEADER COMMENT")
    assert ev["time"][2] is None and ev["time"][0] == ref.epochs["time"][2]
    assert ev["line"].to_list() == [third + 1, third + 4, third + 7]
    assert "{0: 19, 1: 1, 4: 1, 5: 1, 6: 1}" in report.notes[0]


def test_rinex3_event_record(tmp_path):
    lines = _text(ESBC).splitlines()
    first = next(k for k, s in enumerate(lines) if s.startswith(">"))
    lines[first:first] = [f">{'':30}3  1", f"{'ESBC':60}MARKER NAME"]  # new site occupation, blank date
    obs, report = read_rinex_obs(_write(tmp_path, "event.rnx", lines))
    assert obs.events.select("flag", "records").rows() == [(3, 1)] and report.n_rejected == 0
    assert obs.table.height == read_rinex_obs(ESBC)[0].table.height


def test_observation_types_changed_by_an_event_are_refused(tmp_path):
    lines = _text(SYNT).splitlines()
    first = next(k for k, s in enumerate(lines) if "END OF HEADER" in s) + 1
    lines[first:first] = [f"{'':28}4  1", f"{'     2    C1    L1':60}# / TYPES OF OBSERV"]
    with pytest.raises(InputError, match=r"flags.19o:\d+: observation types redefined"):
        read_rinex_obs(_write(tmp_path, "flags.19o", lines))


def test_malformed_records_are_counted_with_file_and_line(tmp_path):
    lines = _text(SYNT).splitlines()
    body = next(k for k, s in enumerate(lines) if "END OF HEADER" in s) + 1
    epochs = [k for k in range(body, len(lines)) if lines[k][18:19] == "."]
    e1, e2, e3, e4 = epochs[1], epochs[3], epochs[5], epochs[7]
    lines[e2 + 3] = lines[e2 + 3][:5] + "X" + lines[e2 + 3][6:]  # unreadable C1 value
    lines[e3] = lines[e3][:35] + "?" + lines[e3][36:]  # unreadable satellite identifier
    lines[e4] = lines[e4][:35] + lines[e4][32:35] + lines[e4][38:]  # the first satellite twice
    del lines[e1 + 4]  # one observation line missing: the record is one line short
    path = _write(tmp_path, "bad.19o", lines)
    obs, report = read_rinex_obs(path)
    ref, _ = read_rinex_obs(SYNT)
    rej = obs.rejected
    assert rej["file"].unique().to_list() == [str(path)]
    assert dict(zip(rej["reason"], rej["line"], strict=True)) == {
        "record_length": e1 + 1,
        "bad_value": e2 + 3,  # e1's record lost a line before it
        "bad_satellite": e3,
        "duplicate_satellite": e4,
    }
    assert report.rejected == {"record_length": 1, "bad_satellite": 1, "duplicate_satellite": 1}
    assert report.invalidated == {"bad_value": 1}
    n1 = ref.epochs["nsat"][1]
    assert (
        obs.table.height == ref.table.height - n1 - 2
    )  # the short epoch, the bad and the repeated satellite
    assert obs.table["C1C"].is_nan().sum() == 1
    with pytest.raises(InputError, match=rf"bad.19o:{e1 + 1}: lines of the record do not match"):
        read_rinex_obs(path, strict=True)


def test_truncated_files(tmp_path):
    lines = _text(SYNT).splitlines()
    last = max(k for k, s in enumerate(lines) if s[18:19] == "." and s[28:29] == "0")
    cut = _write(tmp_path, "cut.19o", lines[: last + 4])
    obs, report = read_rinex_obs(cut)
    assert report.rejected == {"truncated": 1} and report.first_bad == f"{last + 1}: truncated"
    assert obs.epochs.height == 19
    raw = gzip.compress("\n".join(lines).encode())
    broken = tmp_path / "broken.19o.gz"
    broken.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputError, match=r"broken\.19o\.gz: truncated or corrupt gzip"):
        read_rinex_obs(broken)
    head_only = _write(tmp_path, "head.19o", lines[:8])
    with pytest.raises(InputError, match=r"head\.19o: no END OF HEADER"):
        read_rinex_obs(head_only)


def test_unknown_formats_and_versions(tmp_path):
    lines = _text(SYNT).splitlines()
    v4 = [f"{'4.01':>9}" + lines[0][9:], *lines[1:]]
    with pytest.raises(InputError, match=r"v4.19o:1: RINEX version 4.01 not supported"):
        read_rinex_obs(_write(tmp_path, "v4.19o", v4))
    nav = [lines[0][:20] + "N" + lines[0][21:], *lines[1:]]
    with pytest.raises(InputError, match="navigation file, expected observation data"):
        read_rinex_obs(_write(tmp_path, "nav.19o", nav))
    with pytest.raises(InputError, match="not a RINEX file"):
        read_rinex_obs(_write(tmp_path, "ems.txt", ["123 19 01 14 00 00 01 4 53110003FFC0"]))
    crx = gzip.decompress(ESBC.read_bytes())
    bad_crx = tmp_path / "bad.crx"
    bad_crx.write_bytes(crx[:3000] + b"garbage\n" * 3)
    with pytest.raises(InputError, match=r"bad\.crx: cannot expand compressed RINEX"):
        read_rinex_obs(bad_crx)
    with pytest.raises(InputError, match="no such file"):
        read_rinex_obs(tmp_path / "missing.19o")


def test_systems_and_codes_select_columns_and_rows():
    obs, _ = read_rinex_obs(ESBC, systems="G", codes=["C1C", "L1C"])
    assert obs.codes == ["C1C", "L1C"] and set(obs.table["system"]) == {"G"}
    full, _ = read_rinex_obs(ESBC)
    g = full.table.filter(pl.col("system") == "G")
    assert obs.table.select("time", "sat", "C1C", "L1C").equals(g.select("time", "sat", "C1C", "L1C"))
    with pytest.raises(InputError, match=r"observation codes \['C9Z'\] not in the file"):
        read_rinex_obs(ESBC, codes=["C9Z"])


# --------------------------------------------------------------------------- issue 13: nothing lost

BAD = DATA / "bad"  # damaged copies of the fixtures, written by bad/make_rinex_obs_bad.py


def _balanced(report) -> None:
    assert report.unaccounted == 0, report.to_dict()


def _mutated(tmp_path: Path, src: Path, name: str, edit) -> tuple[RinexObs, ReadReport, list[str]]:
    """Read a copy of ``src`` whose lines ``edit(lines, epoch_line_indices)`` changed in place."""
    lines = _text(src).splitlines()
    body = next(k for k, s in enumerate(lines) if "END OF HEADER" in s) + 1
    v3 = lines[0][5:6] == "3"
    epochs = [
        k
        for k in range(body, len(lines))
        if (lines[k][:1] == ">" if v3 else lines[k][18:19] == "." and lines[k][26:28] == "  ")
    ]
    edit(lines, epochs)
    obs, report = read_rinex_obs(_write(tmp_path, name, lines))
    _balanced(report)
    return obs, report, lines


def test_event_flag_and_count_that_swallow_observations_are_rejected():
    """Issue 13: an epoch flag changed to 3 with a count of 99 read the next 99 lines (this epoch's
    observations and all of the next epoch) as header records: 48 of 73 records lost, none
    rejected. The lines after an event's epoch line are not header lines, so the event record is
    malformed: rejected at its line, and the reading goes on at the next epoch line."""
    path = BAD / "rinex2-event-flag-3-count-99.20o"
    lines = path.read_text().splitlines()
    event = next(k for k, s in enumerate(lines) if s[18:19] == "." and s[28:32] == "3 99")
    obs, report = read_rinex_obs(path)
    _balanced(report)
    assert report.rejected == {"bad_event": 1} and report.first_bad == f"{event + 1}: bad_event"
    assert obs.rejected.select("line", "reason").rows() == [(event + 1, "bad_event")]
    assert obs.events.height == 0
    ref, _ = read_rinex_obs(ESBC_V2)
    minutes = [dt.datetime(2020, 6, 25, 0, m, s) for m, s in ((1, 0), (2, 0), (2, 30))]
    assert obs.epochs["time"].to_list() == minutes  # 00:01:30 (the damaged epoch) is the one lost
    assert obs.table.equals(ref.table.filter(pl.col("time").is_in(minutes)))
    assert report.rows_kept == 73 and report.rows_read == 74
    with pytest.raises(InputError, match=rf"count-99\.20o:{event + 1}: event record .* not followed"):
        read_rinex_obs(path, strict=True)


def test_event_records_followed_by_header_lines_are_kept(tmp_path):
    """The check of the lines after an event accepts labels of any case and ``#`` labels."""

    def edit(lines, epochs):
        lines[epochs[2] : epochs[2]] = [
            f"{'':28}4  2",
            f"{'':60}# OF SATELLITES",
            f"{'A COMMENT':60}comment",
        ]

    obs, report, _ = _mutated(tmp_path, SYNT, "event.19o", edit)
    assert report.n_rejected == 0 and obs.events["records"].to_list() == [2]


def test_corrupt_hatanaka_stream_is_refused():
    """Issue 13: one duplicated line of a CRINEX file kept 2 of 3 epochs (86 of 129 records) and
    rejected nothing: ``crx2rnx`` only warned. The warning is now an error naming the file."""
    path = BAD / "crinex-duplicated-line.crx.gz"
    with pytest.raises(
        InputError,
        match=r"duplicated-line\.crx\.gz: corrupt Hatanaka \(CRINEX\) stream: crx2rnx: line 148 : skip",
    ):
        read_rinex_obs(path)


@pytest.mark.parametrize(
    ("case", "rejected"),
    [
        ("hour 24", {"bad_epoch": 1}),
        ("hour 99", {"bad_epoch": 1}),
        ("line deleted", {"record_length": 1}),
        ("line duplicated", {"record_length": 1}),
        ("truncated", {"truncated": 1}),
        ("count 99", {"record_length": 1}),
        ("stray line before the first epoch", {"no_epoch": 1}),
        ("flag 6", {"orphan_slips": 1}),  # cycle slips at a time without observations
    ],
)
def test_epoch_level_rejections_count_one_row_each(tmp_path, case, rejected):
    """Issue 13's rule, rows read = kept + rejected: a rejected epoch record is one row read (its
    satellite count cannot be trusted), a satellite record is one row."""

    def edit(lines, epochs):
        e = epochs[4]
        if case.startswith("hour"):
            lines[e] = lines[e][:10] + case[-2:] + lines[e][12:]
        elif case == "line deleted":
            del lines[e + 5]
        elif case == "line duplicated":
            lines.insert(e + 5, lines[e + 5])
        elif case == "truncated":
            del lines[epochs[-1] + 5 :]
        elif case == "count 99":
            lines[e] = lines[e][:29] + " 99" + lines[e][32:]
        elif case == "flag 6":
            lines[e] = lines[e][:28] + "6" + lines[e][29:]
        else:
            lines.insert(epochs[0], "  garbage")

    _, report, _ = _mutated(tmp_path, SYNT, "mutated.19o", edit)
    ref, _ = read_rinex_obs(SYNT)
    assert report.rejected == rejected
    lost = 0 if "no_epoch" in rejected else ref.epochs["nsat"][-1 if case == "truncated" else 4]
    assert report.rows_kept == ref.table.height - lost
    assert report.rows_read == report.rows_kept + 1


def test_satellite_rejections_and_a_systems_selection_balance(tmp_path):
    def edit(lines, epochs):
        e = epochs[3]
        lines[e] = lines[e][:35] + "?" + lines[e][36:]  # bad satellite identifier
        e = epochs[5]
        lines[e] = lines[e][:35] + "E07" + lines[e][38:]  # Galileo: no observation types in a GPS file

    _, report, _ = _mutated(tmp_path, SYNT, "sats.19o", edit)
    assert report.rejected == {"bad_satellite": 1, "unknown_system": 1}
    full, _ = read_rinex_obs(ESBC)
    _, report = read_rinex_obs(ESBC, systems="G")
    _balanced(report)  # the other systems' records are skipped, not read
    assert report.rows_read == report.rows_kept == full.table.filter(pl.col("system") == "G").height


@pytest.mark.parametrize(
    ("date", "plausible"),
    [
        ("0000 06 25", False),
        ("9999 06 25", False),
        ("1979 12 31", False),
        ("1980 01 05", False),
        ("1980 01 06", True),
        (f"{PLAUSIBLE_END.year - 1} 12 31", True),
        (f"{PLAUSIBLE_END.year} 01 01", False),
        ("2020 13 01", False),
        ("2020 02 30", False),
    ],
)
def test_rinex3_epochs_outside_the_plausible_span_are_rejected(tmp_path, date, plausible):
    def edit(lines, epochs):
        e = epochs[4]
        lines[e] = lines[e][:2] + date + lines[e][12:]

    obs, report, _ = _mutated(tmp_path, ESBC, "years.rnx", edit)
    ref, _ = read_rinex_obs(ESBC)
    if plausible:
        assert report.n_rejected == 0 and obs.table.height == ref.table.height
    else:
        assert report.rejected == {"bad_epoch": 1} and obs.epochs.height == ref.epochs.height - 1
        assert obs.table.height == ref.table.height - ref.epochs["nsat"][4]
    assert obs.table["time"].dt.year().is_between(1980, PLAUSIBLE_END.year - 1).all()


@pytest.mark.parametrize(
    ("yymmdd", "plausible"),
    [
        ("80  1  5", False),  # 1980-01-05: before GPS time
        ("80  1  6", True),
        ("99 12 31", True),  # 1999
        (" 0  1  1", True),  # 2000
        ("79 12 31", False),  # 2079
        (f"{(PLAUSIBLE_END.year - 2000) % 100:2d}  1  1", False),
    ],
)
def test_rinex2_two_digit_years(tmp_path, yymmdd, plausible):
    def edit(lines, epochs):
        e = epochs[2]
        lines[e] = " " + yymmdd + lines[e][9:]

    obs, report, _ = _mutated(tmp_path, SYNT, "years.19o", edit)
    assert report.rejected == ({} if plausible else {"bad_epoch": 1})
    if plausible:
        assert obs.epochs["time"][2].date() == dt.date(
            int(yymmdd[:2]) + (2000 if int(yymmdd[:2]) < 80 else 1900), int(yymmdd[3:5]), int(yymmdd[6:8])
        )


def test_unreadable_header_times_name_file_and_line(tmp_path):
    lines = _text(SYNT).splitlines()
    i = next(k for k, s in enumerate(lines) if "TIME OF FIRST OBS" in s)
    for sec in ("          inf", "          nan", "   99999.0000"):
        lines[i] = lines[i][:30] + sec + lines[i][43:]
        with pytest.raises(InputError, match=rf"first\.19o:{i + 1}: date out of range"):
            read_rinex_obs(_write(tmp_path, "first.19o", lines))
