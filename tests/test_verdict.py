"""The verdict rules of overbound.verdict on constructed evidence and on simulated campaigns."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.methods.counting import count_kpis
from overbound.methods.evidence import (
    CountedAvailability,
    ServiceEvidence,
    TailCounts,
    counted_evidence,
    loss_events,
    run_clusters,
)
from overbound.report.json import provenance_dict, summary_dict
from overbound.services import SERVICES, resolve_services
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.proportion import Bounds
from overbound.verdict import (
    FAIL,
    KINDS,
    NOT_DEMONSTRATED,
    PASS,
    assess,
    availability_verdict,
    overall_verdict,
    tail_adequacy,
)


def _epochs(n: int = 7200, *, hmi_at: int | None = None, station: str = "A") -> pl.DataFrame:
    rng = np.random.default_rng(1)
    t = np.datetime64("2024-01-07T00:00:00", "us") + (np.arange(n) * 1_000_000).astype("timedelta64[us]")
    vpe = rng.normal(0, 1.0, n)
    vpl = np.full(n, 20.0)
    if hmi_at is not None:
        vpe[hmi_at] = 40.0  # PE > VAL while VPL < VAL: HMI for every service with VAL <= 40 m
    return pl.DataFrame(
        {
            "time": t,
            "station": station,
            "hpe": np.abs(rng.normal(0, 1.0, n)),
            "vpe": vpe,
            "hpl": 15.0,
            "vpl": vpl,
        }
    )


def _availability(k: int, n: int, lo: float, hi: float) -> ServiceEvidence:
    a = CountedAvailability(n, k, float(n), 1.0, False, Bounds(k / n, lo, hi, 0.95))
    return ServiceEvidence(a, None, {}, {})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("lo", "hi", "expected"),
    [(0.991, 0.999, PASS), (0.95, 0.989, FAIL), (0.985, 0.995, NOT_DEMONSTRATED)],
)
def test_availability_verdict_follows_the_bounds(lo, hi, expected):
    v = availability_verdict(_availability(990, 1000, lo, hi), SERVICES["LPV"])
    assert v.verdict == expected
    assert v.evidence[0].lower == lo and v.evidence[0].upper == hi
    assert "99 %" in v.sentence


def test_an_observed_hmi_always_fails_integrity():
    a = analyze(_epochs(hmi_at=3000), services=["LPV-200"], parametric=True, evt=None, evt_n_boot=50)
    verdicts = assess(a).services["LPV-200"]
    assert verdicts.integrity.verdict == FAIL
    assert verdicts.pl_bounding.verdict == FAIL  # an HMI is an MI
    assert verdicts.overall.verdict == FAIL
    assert "observed" in verdicts.integrity.sentence


def test_adequacy_rejects_a_model_that_predicts_fewer_exceedances_than_observed():
    counts = TailCounts("vertical", (0.3, 0.5, 0.7), 10**6, (400, 40, 4), (40, 8, 2), 0.85, None, 360.0)
    optimistic = tail_adequacy(counts, epochs_above=lambda s: 1e6 * np.exp(-0.5 * (s / 0.05) ** 2))
    assert optimistic.rejected
    conservative = tail_adequacy(counts, epochs_above=lambda s: 1e6 * 1e-3 * np.exp(-(s - 0.3) / 0.2) * 3)
    assert not conservative.rejected
    assert [c.level for c in conservative.checks] == [0.3, 0.5, 0.7, 0.85]
    # a model of the tail above 0.5 is only checked where it applies
    above = tail_adequacy(counts, clusters_above=lambda s: 10.0, lowest_level=0.5)
    assert [c.level for c in above.checks] == [0.5, 0.7, 0.85]


def test_counted_evidence_agrees_with_the_counting_and_pools_stations():
    table = pl.concat([_epochs(station="A"), _epochs(station="B")])
    levels = resolve_services(["LPV-200", "NPA"])
    counting = count_kpis(table, levels)
    ev = counted_evidence(table, counting, levels)
    assert set(ev.by_station) == {"A", "B"}
    for name in ("LPV-200", "NPA"):
        pooled = ev.pooled.services[name].availability
        assert pooled.n_available == counting.services[name].combined.n_available
        assert pooled.n == sum(ev.by_station[s].services[name].availability.n for s in "AB")
    assert ev.pooled.tails["vertical"].n_epochs == 2 * 7200


def test_run_clusters_and_loss_events():
    assert run_clusters(np.array([0.0, 10.0, 300.0, 1000.0, 1100.0]), 360.0) == 2
    assert run_clusters(np.array([0.0, 10.0, 400.0, 1000.0, 1100.0]), 360.0) == 3
    t = np.arange(20.0)
    avail = np.ones(20, dtype=bool)
    avail[5] = avail[6] = avail[12] = False
    assert loss_events(t, avail, 1.0, 15.0) == 1  # two losses 7 s apart: one event for a 15 s window
    assert loss_events(t, avail, 1.0, 5.0) == 2
    gap = np.delete(t, 15)  # a missing epoch is a loss too
    assert loss_events(gap, np.ones(19, dtype=bool), 1.0, 15.0) == 1


def test_overall_rule():
    from overbound.verdict import Verdict

    def v(x):
        return Verdict("availability", x, "", "", "")

    assert overall_verdict([v(PASS), v(PASS)]).verdict == PASS
    assert overall_verdict([v(PASS), v(NOT_DEMONSTRATED)]).verdict == NOT_DEMONSTRATED
    assert overall_verdict([v(NOT_DEMONSTRATED), v(FAIL)]).verdict == FAIL


def _analyze_all(table, services):
    """Every method on ``table`` (vertical confidence level, both EVT axes, parametric; 100 resamples)."""
    return analyze(
        table, services=services, confidence=("vertical",), evt=None, parametric=True, evt_n_boot=100
    )


@pytest.fixture(scope="module")
def gaussian_campaign():
    sim = simulate(SimulationConfig(days=3, seed=7, sigma_ratio=0.5, tail_fraction=0.0))
    return _analyze_all(sim.table, ["NPA", "LPV-200"])


def test_well_overbounded_campaign_passes_pl_bounding_on_the_floored_evt(gaussian_campaign):
    v = assess(gaussian_campaign).services["LPV-200"].pl_bounding
    assert v.verdict == PASS
    evt = [e for e in v.evidence if e.method.startswith("EVT")]
    assert len(evt) == 2 and all(e.upper is not None and e.upper > 0 for e in evt)  # never a 0 bound
    assert all("floored at 0" in e.assumption or "> 0" in e.assumption for e in evt)
    assert sum(e.upper for e in evt) <= 2e-7


def test_summary_verdicts_and_provenance(gaussian_campaign, tmp_path):
    f = tmp_path / "deep" / "input.csv"
    f.parent.mkdir()
    f.write_bytes(b"time,station\n")
    prov = provenance_dict([f], ["overbound", "analyze", str(f), "-o", str(tmp_path / "out")], {"x": f})
    doc = summary_dict(gaussian_campaign, provenance=prov)
    assert set(doc["verdicts"]) == {"NPA", "LPV-200"}
    for per in doc["verdicts"].values():
        assert set(per) == {*KINDS, "overall"}
        for v in per.values():
            assert v["verdict"] in ("pass", "fail", "not demonstrated")
            assert {"requirement", "basis", "sentence", "evidence"} <= set(v)
    assert doc["verdicts_by_station"] == {}
    p = doc["provenance"]
    assert p["inputs"] == [
        {"name": "input.csv", "size": 13, "sha256": hashlib.sha256(b"time,station\n").hexdigest()}
    ]
    assert p["command"] == ["overbound", "analyze", "input.csv", "-o", "out"] and p["options"] == {
        "x": "input.csv"
    }
    assert str(tmp_path) not in json.dumps(doc, default=str)


def _consistent(v) -> bool:
    """A verdict never contradicts the evidence listed under it."""
    votes = {e.vote for e in v.evidence}
    if v.verdict == PASS:
        return "fail" not in votes
    if v.verdict == FAIL:
        return "fail" in votes or v.kind == "overall"
    return True


@pytest.mark.parametrize("anomaly", ["band:15:16:3", "bias:30:1800:12:vertical"])
def test_anomalies_fail_pl_bounding_and_verdicts_match_their_evidence(anomaly):
    sim = simulate(SimulationConfig(days=3, seed=5, tail_fraction=0.0, anomalies=(anomaly,)))
    a = _analyze_all(sim.table, ["APV-I", "LPV-200"])
    result = assess(a)
    for sv in result.services.values():
        assert sv.pl_bounding.verdict != PASS  # the true risk fails on both anomalies
        for k in (*KINDS, "overall"):
            assert _consistent(sv.get(k)), (sv.service, k, sv.get(k).sentence)


def test_several_stations_get_their_own_verdicts():
    table = pl.concat([_epochs(station="A"), _epochs(station="B", hmi_at=100)])
    a = analyze(table, services=["LPV-200"])
    result = assess(a)
    assert set(result.by_station) == {"A", "B"}
    assert result.by_station["B"]["LPV-200"].integrity.verdict == FAIL  # B saw the HMI
    assert result.by_station["A"]["LPV-200"].integrity.verdict != FAIL
    assert result.services["LPV-200"].integrity.verdict == FAIL  # the pooled network did too
    doc = summary_dict(a, assessment=result)
    assert set(doc["verdicts_by_station"]) == {"A", "B"}
    assert doc["verdicts_by_station"]["B"]["LPV-200"]["integrity"]["verdict"] == "fail"


def test_r8_at_the_analysis_own_risk_is_the_band_confidence_already_computed() -> None:
    """R8 re-evaluates each rated band at each service's risk per sample; at the confidence
    analysis' own risk (1e-7, NPA's) it takes the band's confidence level, which is the same call:
    equal to the last bit, and not evaluated again."""
    import overbound.verdict as verdict
    from overbound.methods.confidence_level import confidence_analysis

    sim = simulate(SimulationConfig(days=2, seed=1, tail_fraction=0.0))
    cl = confidence_analysis(sim.table, axis="horizontal", min_samples=60, max_pl=25.0)
    rated = [(b, s) for b, s in zip(cl.bins, cl.samples, strict=True) if b.sufficient]
    assert len(rated) > 3
    for b, s in rated:
        assert verdict.band_confidence(s.pl, b.mean, b.sigma_inflated, b.n, cl.risk, cl.axis) == b.confidence
    npa = resolve_services(["NPA"])
    assert cl.risk == npa[0].integrity_risk
    assert verdict.band_confidence_inputs([cl], npa) == {}  # nothing left to evaluate at NPA's risk
    lpv = verdict.band_confidence_inputs([cl], resolve_services(["LPV"]))
    assert lpv and all(k[3] == 2e-7 for k in lpv)
