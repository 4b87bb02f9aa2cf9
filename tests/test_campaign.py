"""The campaign analysis by partition (issue 14): the same counting KPIs as the pooled table, in
this process, on a local cluster and on a real ``dask scheduler`` with two ``dask worker``
processes; a cache that is reused and invalidated; unreadable partitions counted, not fatal."""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from pathlib import Path

import pytest

from overbound.campaign import campaign_client, count_campaign, uncached_partitions
from overbound.io.dataset import partitions, read_dataset
from overbound.methods.counting import count_kpis
from overbound.methods.evidence import counted_evidence
from overbound.services import resolve_services
from overbound.simulate import SimulationConfig, write_simulation_dataset

sys.path.insert(0, str(Path(__file__).parent / "methods"))
from test_counting_partitions import assert_same

SERVICES = resolve_services(None)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """3 stations x 7 days at 10 s, with gaps (some across midnight)."""
    path = tmp_path_factory.mktemp("campaign") / "ds"
    cfg = SimulationConfig(days=7, interval_s=10.0, stations=3, seed=5, gap_rate_per_day=3.0, gap_mean_s=600)
    write_simulation_dataset(cfg, path)
    return path


@pytest.fixture(scope="module")
def pooled(dataset: Path):
    table, _ = read_dataset(dataset, columns=("alert",))
    return count_kpis(table, SERVICES)


def _copy(dataset: Path, tmp_path: Path) -> Path:
    out = tmp_path / "ds"
    shutil.copytree(dataset, out, ignore=shutil.ignore_patterns(".overbound"))
    return out


def test_in_process_equals_pooled_table(dataset: Path, pooled, tmp_path: Path) -> None:
    ds = _copy(dataset, tmp_path)
    result = count_campaign(ds, SERVICES)
    assert_same(result.counting, pooled)
    assert result.failures == () and result.n_partitions == 21
    assert result.daily.height == 21 and result.daily["n_epochs"].sum() == pooled.n_total


def test_cache_is_reused_then_invalidated(dataset: Path, pooled, tmp_path: Path) -> None:
    ds = _copy(dataset, tmp_path)
    first = count_campaign(ds, SERVICES)
    assert first.n_cached == 0 and first.n_computed > 0
    again = count_campaign(ds, SERVICES)
    assert again.n_computed == 0 and again.n_cached == first.n_computed
    assert_same(again.counting, pooled)
    # a replaced partition (new file, as ingest writes it) is computed again, alone in pass 1
    part = partitions(ds)[4].path
    data = part.read_bytes()
    part.unlink()
    part.write_bytes(data)
    os.utime(part, ns=(time.time_ns(), time.time_ns() + 10**9))
    third = count_campaign(ds, SERVICES)
    assert 1 <= third.n_computed <= 3, third.n_computed  # pass 1, maybe values and windows
    assert_same(third.counting, pooled)
    assert uncached_partitions(ds, SERVICES) == 0
    os.utime(part, ns=(time.time_ns(), time.time_ns() + 2 * 10**9))
    assert uncached_partitions(ds, SERVICES) == 1  # what the command weighs against a cluster
    # a stale cache entry of another overbound version is never used
    for cache in ds.rglob(".overbound/pass1.pkl"):
        cache.write_bytes(b"not a pickle")
    assert_same(count_campaign(ds, SERVICES).counting, pooled)


def test_evidence_by_partition_is_cached_and_equals_the_pooled_table(dataset: Path, tmp_path: Path) -> None:
    """The verdicts' evidence (passes 3 and 4) equals counted_evidence of the pooled table, from the
    cache too; a replaced partition recomputes its own parts only (the data are the same here, so
    are the station's percentiles), and an unreadable one is left out of everything."""
    table, _ = read_dataset(dataset, columns=("alert",))
    expected = counted_evidence(table, count_kpis(table, SERVICES), SERVICES)
    ds = _copy(dataset, tmp_path)
    first = count_campaign(ds, SERVICES, evidence=True)
    assert_same(first.evidence, expected)
    again = count_campaign(ds, SERVICES, evidence=True)
    assert again.n_computed == 0 and again.n_cached == 3 * 21  # each station whole, in 3 passes
    assert_same(again.evidence, expected)
    # a station's evidence parts are not kept with its merged pass 2: its drafted evidence is;
    # without it, the station is taken from its partitions' parts
    drafts = sorted(ds.glob("station=*/.overbound/draft.pkl"))
    assert len(drafts) == 3
    drafts[1].unlink()
    assert_same(count_campaign(ds, SERVICES, evidence=True).evidence, expected)
    part = partitions(ds)[4].path
    os.utime(part, ns=(time.time_ns(), time.time_ns() + 10**9))
    third = count_campaign(ds, SERVICES, evidence=True)
    assert 4 <= third.n_computed <= 5, third.n_computed  # pass 1; evidence, values (windows); bounds
    assert_same(third.evidence, expected)
    bad = partitions(ds)[8]
    bad.path.write_bytes(b"PAR1 this is not parquet")
    fourth = count_campaign(ds, SERVICES, evidence=True)
    assert [f.key for f in fourth.failures] == [bad.key]
    rest, _ = read_dataset(ds, columns=("alert",), skip={bad.key})
    assert_same(fourth.evidence, counted_evidence(rest, count_kpis(rest, SERVICES), SERVICES))


def test_unreadable_partition_is_reported_and_the_rest_goes_on(dataset: Path, tmp_path: Path) -> None:
    ds = _copy(dataset, tmp_path)
    bad = partitions(ds)[8]
    bad.path.write_bytes(b"PAR1 this is not parquet")
    result = count_campaign(ds, SERVICES, cache=False)
    (failure,) = result.failures
    assert (failure.station, failure.date) == (bad.station, bad.date.isoformat()) and failure.reason
    bad.path.unlink()
    shutil.rmtree(bad.path.parent)
    table, _ = read_dataset(ds, columns=("alert",))
    assert_same(result.counting, count_kpis(table, SERVICES))


def test_a_partition_without_a_required_column_is_reported_with_the_reader_reason(
    dataset: Path, tmp_path: Path
) -> None:
    """A partition that is Parquet but not an epoch table goes through the epoch reader, whose
    one-line reason is the failure's (an InputError once crashed the run instead)."""
    import polars as pl

    ds = _copy(dataset, tmp_path)
    bad = partitions(ds)[3]
    pl.read_parquet(bad.path).drop("vpl").write_parquet(bad.path)
    result = count_campaign(ds, SERVICES, cache=False)
    (failure,) = result.failures
    assert failure.key == bad.key
    assert "vpl" in failure.reason and str(bad.path) not in failure.reason


def test_local_cluster_equals_pooled_table(dataset: Path, pooled, tmp_path: Path) -> None:
    with campaign_client(workers=2) as client:
        result = count_campaign(_copy(dataset, tmp_path), SERVICES, client=client)
    assert_same(result.counting, pooled)


def test_real_scheduler_and_two_workers(dataset: Path, pooled, tmp_path: Path, scheduler: str) -> None:
    client = campaign_client(scheduler=scheduler)
    try:
        client.wait_for_workers(2, timeout=60)
        assert len(client.scheduler_info()["workers"]) == 2
        result = count_campaign(_copy(dataset, tmp_path), SERVICES, client=client)
        ran_on = client.run(os.getpid)
    finally:
        client.close()
    assert len(set(ran_on.values())) == 2
    assert_same(result.counting, pooled)


# --------------------------------------------------------------------------------------------------
# the command line: the acceptance tests


def _analyze(args: list[str]) -> dict:
    from click.testing import CliRunner

    from overbound.cli import main

    res = CliRunner().invoke(main, ["analyze", *args])
    assert res.exit_code == 0, res.output
    out = Path(args[args.index("-o") + 1])
    return json.loads((out / "summary.json").read_text())


def _numbers(doc: dict) -> dict:
    """The summary without what names the input (title, inputs, provenance) or the run's options."""
    return {k: v for k, v in doc.items() if k not in ("title", "inputs", "provenance")}


def test_dataset_and_one_file_give_the_same_summary(dataset: Path, tmp_path: Path) -> None:
    """3 stations x 7 days: every number of summary.json, the verdicts and the methods included,
    equal for the dataset analysed by partition and for the same epochs as one file."""
    from overbound.io.table import write_epochs

    table, _ = read_dataset(dataset)
    one = tmp_path / "network.parquet"
    write_epochs(table, one)
    ds = _copy(dataset, tmp_path)
    common = ["--no-evt", "--no-parametric"]  # the methods read the same pooled table; kept short
    file_doc = _analyze([str(one), "-o", str(tmp_path / "file"), *common])
    ds_doc = _analyze([str(ds), "-o", str(tmp_path / "dataset"), "--workers", "0", *common])
    network = ds_doc.pop("network")
    assert _numbers(file_doc) == _numbers(ds_doc)
    assert file_doc["services"]["LPV"]["continuity"]["combined"]["n_windows"] > 0
    assert network["partitions"] == network["partitions_analysed"] == 21 and network["unreadable"] == []
    assert sum(len(days) for days in network["days"].values()) == 21
    assert ds_doc["verdicts"] and set(ds_doc["stations"]) == {"SIM01", "SIM02", "SIM03"}


def test_verdicts_by_partition_on_a_real_scheduler_equal_one_file(
    dataset: Path, tmp_path: Path, scheduler
) -> None:
    """Without methods the pooled table is never read: the counting and the verdicts' evidence
    come from the partitions (on two ``dask worker`` processes), equal to the same epochs as one
    file, and so are the verdicts."""
    from overbound.io.table import write_epochs

    table, _ = read_dataset(dataset)
    one = tmp_path / "network.parquet"
    write_epochs(table, one)
    ds = _copy(dataset, tmp_path)
    common = ["--no-confidence", "--no-evt", "--no-parametric"]
    file_doc = _analyze([str(one), "-o", str(tmp_path / "file"), *common])
    ds_doc = _analyze([str(ds), "-o", str(tmp_path / "dataset"), "--scheduler", scheduler, *common])
    ds_doc.pop("network")
    assert _numbers(file_doc) == _numbers(ds_doc)
    assert file_doc["verdicts"] == ds_doc["verdicts"] and ds_doc["verdicts"]["LPV"]
    assert file_doc["verdicts_by_station"] == ds_doc["verdicts_by_station"]


def test_methods_by_partition_on_a_real_scheduler_equal_one_file(
    dataset: Path, tmp_path: Path, scheduler
) -> None:
    """The EVT tail extrapolation, the PL confidence level and the parametric analysis reduce the
    partitions (their passes on the two ``dask worker`` processes, no pooled table read): their JSON
    files and the summary, verdicts included, equal those of the same epochs as one file."""
    from overbound.io.table import write_epochs

    table, _ = read_dataset(dataset)
    one = tmp_path / "network.parquet"
    write_epochs(table, one)
    ds = _copy(dataset, tmp_path)
    file_doc = _analyze([str(one), "-o", str(tmp_path / "file")])
    ds_doc = _analyze([str(ds), "-o", str(tmp_path / "dataset"), "--scheduler", scheduler])
    ds_doc.pop("network")
    assert _numbers(file_doc) == _numbers(ds_doc)
    by_file, by_parts = ((tmp_path / d / "parametric.json").read_text() for d in ("file", "dataset"))
    assert by_file == by_parts and json.loads(by_parts)["vertical"]["weibull"]
    for axis in ("vertical", "horizontal"):
        name = f"evt-{axis}.json"
        by_file, by_parts = (json.loads((tmp_path / d / name).read_text()) for d in ("file", "dataset"))
        for doc in (by_file, by_parts):
            doc.pop("timings", None)
        assert by_file == by_parts and by_parts["p_mi_95"] is not None
        name = f"confidence-{axis}.json"
        by_file, by_parts = ((tmp_path / d / name).read_text() for d in ("file", "dataset"))
        assert by_file == by_parts and json.loads(by_parts)["bins"]


def test_counting_only_on_a_real_scheduler_equals_in_process(
    dataset: Path, tmp_path: Path, scheduler, monkeypatch
) -> None:
    ds = _copy(dataset, tmp_path)
    local = _analyze(
        [str(ds), "-o", str(tmp_path / "local"), "--counting-only", "--workers", "0", "--no-cache"]
    )
    # the dataset given relative to a folder that is not the workers' own: they still find it
    monkeypatch.chdir(tmp_path)
    remote = _analyze(["ds", "-o", str(tmp_path / "remote"), "--counting-only", "--scheduler", scheduler])
    assert _numbers(local) == _numbers(remote)
    from overbound.report.provenance import base_word  # how summary.json records the command line

    assert base_word(scheduler) == scheduler  # an address stays whole
    assert base_word("s3://bucket/x/net") == "net"
    assert local["verdicts"] == {} and local["network"]["partitions_analysed"] == 21
    html = (tmp_path / "remote" / "report.html").read_text()
    assert 'id="network"' in html and 'data-figure="heatmap-LPV"' in html and "Not assessed" in html


def test_time_window_reads_the_days_it_needs_and_cuts_the_edges(dataset: Path, tmp_path: Path) -> None:
    """--start/--end on a dataset: the epochs start <= t < end, as the pooled table filtered."""
    import datetime as dt

    import polars as pl

    window = (dt.datetime(2024, 1, 8, 6, 30), dt.datetime(2024, 1, 10))  # cuts one day, ends at midnight
    table, _ = read_dataset(dataset, columns=("alert",))
    table = table.filter(pl.col("time") >= window[0], pl.col("time") < window[1])
    result = count_campaign(_copy(dataset, tmp_path), SERVICES, time_range=window)
    assert result.n_partitions == 3 * 2  # 2024-01-08 and 2024-01-09 of each station
    assert_same(result.counting, count_kpis(table, SERVICES))


def test_a_dataset_refuses_to_write_the_pooled_table(dataset: Path, tmp_path: Path) -> None:
    from click.testing import CliRunner

    from overbound.cli import main

    args = [
        str(dataset),
        "-o",
        str(tmp_path / "out"),
        "--counting-only",
        "--epochs",
        str(tmp_path / "e.parquet"),
    ]
    res = CliRunner().invoke(main, ["analyze", *args])
    assert res.exit_code == 2 and "a dataset's analysis does not read" in res.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "e.parquet").exists()


def test_no_method_reads_the_pooled_table(dataset: Path, tmp_path: Path, monkeypatch) -> None:
    """Every method runs by partition: analysing a dataset with all of them never reads it whole."""
    import overbound.io.dataset as io_dataset
    from overbound.analysis import analyze

    def refuse(*args, **kwargs):
        raise AssertionError("the pooled table was read")

    monkeypatch.setattr(io_dataset, "read_dataset", refuse)
    monkeypatch.setattr("overbound.io.open.read_dataset", refuse)
    done = analyze([_copy(dataset, tmp_path)], confidence=None, evt=None, evt_n_boot=20, parametric=True)
    assert done.parametric.vertical and done.parametric.horizontal and done.evt and done.confidence
    assert done.table.height == 0 and not done.method_failures


def test_the_band_confidences_of_the_verdicts_are_computed_ahead(
    dataset: Path, tmp_path: Path, monkeypatch
) -> None:
    """A dataset's analysis computes R8's confidence levels (each rated band at each service's risk)
    on its runner: the verdicts then compute none, and are those they give computing them."""
    import dataclasses

    import overbound.verdict as verdict
    from overbound.analysis import analyze

    done = analyze([_copy(dataset, tmp_path)], confidence=None, evt=())
    assert done.band_confidences
    assert set(done.band_confidences) == set(verdict.band_confidence_inputs(done.confidence, done.services))
    own = verdict.assess(dataclasses.replace(done, band_confidences={}))

    def refuse(*args):
        raise AssertionError("a band's confidence computed again")

    monkeypatch.setattr(verdict, "band_confidence", refuse)
    assert repr(verdict.assess(done)) == repr(own)


def test_a_dataset_starts_the_figure_processes_at_its_report_a_file_at_once(
    dataset: Path, tmp_path: Path, monkeypatch
) -> None:
    """The figure pool holds ~160 MB per process: a campaign's analysis (minutes, on Dask workers)
    starts it at the report's first figure, a file's analysis while it runs (to have it warm)."""
    import overbound.analysis
    from overbound.io.table import write_epochs
    from overbound.report.rendering import ENV_PROCESSES, active_renderer

    monkeypatch.setenv(ENV_PROCESSES, "2")
    started: list[bool] = []
    run = overbound.analysis.analyze

    def spy(*args, **kwargs):
        started.append(active_renderer().started)
        return run(*args, **kwargs)

    monkeypatch.setattr(overbound.analysis, "analyze", spy)
    table, _ = read_dataset(dataset)
    one = tmp_path / "network.parquet"
    write_epochs(table, one)
    ds = _copy(dataset, tmp_path)
    _analyze([str(ds), "-o", str(tmp_path / "dataset"), "--workers", "0", "--counting-only"])
    _analyze([str(one), "-o", str(tmp_path / "file"), "--no-confidence", "--no-evt", "--no-parametric"])
    assert started == [False, True]
    report = (tmp_path / "dataset" / "report.html").read_text()
    assert report.count("data:image/png;base64,") > 3  # the deferred pool drew the figures


def test_workers_and_scheduler_are_one_or_the_other(dataset: Path, tmp_path: Path, monkeypatch) -> None:
    """--workers with --scheduler is refused; an explicit --workers wins over $DASK_SCHEDULER_ADDRESS
    (here an address where nothing listens: using it would fail); with the variable set, a plain
    file is analysed as ever."""
    from click.testing import CliRunner

    from overbound.cli import main

    ds = _copy(dataset, tmp_path)
    args = ["analyze", str(ds), "-o", str(tmp_path / "a"), "--counting-only", "--no-cache"]
    res = CliRunner().invoke(main, [*args, "--workers", "0", "--scheduler", "tcp://127.0.0.1:9"])
    assert res.exit_code == 2 and "give one" in res.output
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://127.0.0.1:9")
    doc = _analyze([*args[1:], "--workers", "0"])
    assert doc["network"]["partitions_analysed"] == 21
    pos = Path(__file__).parents[1] / "src" / "overbound" / "data" / "uslo-2006-361-waas.pos.gz"
    reference = ["--reference", "35.311803,-120.661092,134.6419"]
    plain = _analyze([str(pos), *reference, "-o", str(tmp_path / "plain"), "--no-evt", "--no-parametric"])
    assert plain["epochs"]["total"] > 0
