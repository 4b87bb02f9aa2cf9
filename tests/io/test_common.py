"""Row rules shared by every reader, and the epoch-table validator."""

from __future__ import annotations

import datetime as dt

import numpy as np
import polars as pl
import pytest

from overbound.io._common import RowLog, finalize_epochs
from overbound.io.schema import InputError, empty_epochs, validate_epochs

T0 = dt.datetime(2024, 1, 7)


def _raw(seconds, hpl=None, vpl=None, hpe=None, vpe=None, station="S"):
    n = len(seconds)
    return pl.DataFrame(
        {
            "time": [T0 + dt.timedelta(seconds=s) for s in seconds],
            "station": [station] * n,
            "hpe": hpe if hpe is not None else [1.0] * n,
            "vpe": vpe if vpe is not None else [-1.0] * n,
            "hpl": hpl if hpl is not None else [10.0] * n,
            "vpl": vpl if vpl is not None else [15.0] * n,
            "_line": list(range(10, 10 + n)),
        }
    )


def test_clean_rows_pass_through():
    table, rep = finalize_epochs(_raw([0, 1, 2]), RowLog("f.pos", rows_read=3), format="x")
    assert table.height == 3 and rep.rows_kept == 3 and rep.n_rejected == 0 and rep.first_bad == ""
    assert table.schema["time"] == pl.Datetime("us") and table.schema["station"] == pl.Categorical()
    assert "_line" not in table.columns


def test_duplicate_time_rejected_and_counted():
    table, rep = finalize_epochs(_raw([0, 1, 1, 1, 2]), RowLog("f.pos", rows_read=5), format="x")
    assert table.height == 3
    assert rep.rejected == {"duplicate_time": 2}
    assert rep.first_bad.startswith("12: duplicate time")


def test_duplicate_time_strict_raises_with_line():
    with pytest.raises(InputError, match=r"^f.pos:12: duplicate time"):
        finalize_epochs(_raw([0, 1, 1]), RowLog("f.pos", strict=True), format="x")


def test_backward_time_raises_with_line():
    with pytest.raises(InputError, match=r"^f.pos:12: backward time"):
        finalize_epochs(_raw([0, 2, 1]), RowLog("f.pos"), format="x")


def test_same_time_other_station_is_not_a_duplicate():
    raw = pl.concat([_raw([0, 1], station="A"), _raw([0, 1], station="B")])
    table, rep = finalize_epochs(raw, RowLog("f"), format="x")
    assert table.height == 4 and rep.n_rejected == 0


@pytest.mark.parametrize(
    ("col", "value", "reason"),
    [("hpl", -1.0, "negative_pl"), ("vpl", float("nan"), "nan_pl"), ("vpe", float("nan"), "nan_error")],
)
def test_unusable_values_invalidate_the_epoch(col, value, reason):
    values = {col: [10.0, value, 10.0]}
    table, rep = finalize_epochs(_raw([0, 1, 2], **values), RowLog("f"), format="x")
    assert table.height == 3  # the epoch stays ...
    assert np.isnan(table["hpl"][1]) and np.isnan(table["vpe"][1])  # ... as a no-solution epoch
    assert rep.invalidated == {reason: 1}
    assert rep.first_bad.startswith("11: " + reason)


def test_no_solution_rows_are_not_counted_as_invalid():
    nan = float("nan")
    raw = _raw([0, 1], hpl=[10.0, nan], vpl=[10.0, nan], hpe=[1.0, nan], vpe=[1.0, nan])
    _, rep = finalize_epochs(raw, RowLog("f"), format="x")
    assert rep.invalidated == {}


def test_validate_missing_column():
    with pytest.raises(InputError, match="missing required column"):
        validate_epochs(pl.DataFrame({"time": [T0]}), "t.csv")


def test_validate_negative_and_order():
    good = _raw([0, 1]).drop("_line")
    assert validate_epochs(good).height == 2
    with pytest.raises(InputError, match=r"t:2: negative hpl"):
        validate_epochs(good.with_columns(pl.Series("hpl", [1.0, -2.0])), "t")
    with pytest.raises(InputError, match=r"t:3: duplicate time"):
        validate_epochs(_raw([0, 1, 1]).drop("_line"), "t")


def test_empty_table_has_required_columns():
    assert empty_epochs().columns == ["time", "station", "hpe", "vpe", "hpl", "vpl"]


def test_a_time_window_recounts_the_invalidated_rows_it_removes(tmp_path):
    """kept + rejected = read, and the invalidated rows are among the kept ones, after a time window."""
    import datetime as dt

    from overbound.io.open import read

    t = [f"2024-01-07T00:00:{s:02d}" for s in range(10)]
    hpl = ["nan", "5", "-1", "5", "5", "nan", "5", "5", "5", "nan"]  # invalidated at 0, 2, 5, 9
    rows = [f"{a},S,1.0,0.5,{h},8.0" for a, h in zip(t, hpl, strict=True)]
    path = tmp_path / "rx.csv"
    path.write_text("time,station,hpe,vpe,hpl,vpl\n" + "\n".join(rows) + "\n")
    table, whole = read(path)
    assert whole.invalidated == {"nan_pl": 3, "negative_pl": 1}
    window = (dt.datetime(2024, 1, 7, 0, 0, 1), dt.datetime(2024, 1, 7, 0, 0, 6))  # seconds 1-5
    table, cut = read(path, time_range=window)
    assert (cut.rows_read, cut.rows_kept, cut.rejected) == (10, 5, {"outside_time_range": 5})
    assert cut.invalidated == {"negative_pl": 1, "nan_pl": 1}  # rows 2 and 5 are inside, 0 and 9 not
    assert int(table["hpl"].is_nan().sum()) == sum(cut.invalidated.values())
    assert cut.invalid_rows is None  # the bookkeeping is not carried beyond the read
