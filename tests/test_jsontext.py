"""Deterministic JSON: the lazily formatted sample times and the streamed writer give dumps' bytes."""

from __future__ import annotations

import json

import numpy as np

from overbound.jsontext import IsoTimes, dump, dumps


def _times(n: int) -> np.ndarray:
    rng = np.random.default_rng(3)
    return np.sort(1_704_585_600_000_000 + rng.integers(0, 10**12, n))  # 2024-01-07 + up to 11 days, in us


def test_iso_times_read_as_numpy_millisecond_strings():
    us = _times(70_000)  # more than one formatting block
    want = np.datetime_as_string(us.astype("datetime64[us]"), unit="ms").tolist()
    t = IsoTimes(us)
    assert len(t) == len(want) and list(t) == want and t[5] == want[5] and list(t[10:20]) == want[10:20]
    assert t == tuple(want) and t == want and t != want[:-1] and t != (*want[:-1], "x")
    assert IsoTimes.parse(want) == t  # the JSON form back, microseconds floored to the millisecond
    assert IsoTimes([]) == () and hash(IsoTimes(us)) == hash(IsoTimes(us.copy()))


def test_dump_writes_the_bytes_of_dumps(tmp_path):
    us = _times(100_003)
    doc = {"b": [{"epochs": IsoTimes(us), "x": 0.1 + 0.2}], "a": float("nan"), "c": np.int64(3)}
    plain = {"b": [{"epochs": list(IsoTimes(us)), "x": 0.1 + 0.2}], "a": float("nan"), "c": np.int64(3)}
    text = dumps(doc)
    assert text == dumps(plain)
    assert dump(doc, tmp_path / "d.json").read_bytes() == text.encode("utf-8")
    back = json.loads(text)
    assert back["b"][0]["epochs"][:2] == list(IsoTimes(us[:2])) and back["a"] is None
    assert dumps({"e": IsoTimes([])}) == '{\n  "e": []\n}\n'


def test_to_jsonable_of_iso_times_reads_as_its_list():
    from overbound.jsontext import to_jsonable

    want = list(IsoTimes(_times(10)))
    got = to_jsonable({"e": IsoTimes(_times(10))})["e"]
    assert got == want and want == got and got[3] == want[3] and len(got) == 10 and repr(got) == repr(want)
