"""The ``overbound`` command line: parses arguments and calls public functions only."""

from __future__ import annotations

import contextlib
import datetime
import functools
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from importlib.resources import as_file, files
from pathlib import Path

import click
from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from overbound import __version__
from overbound.io.dataset import is_dataset
from overbound.io.geodesy import MEAN_POSITION, MeanPosition, Reference
from overbound.io.open import FORMATS
from overbound.io.schema import InputError
from overbound.output import OutputError, StagedDirectory, staged_directory, staged_files

__all__ = ["main"]

# Logs (no terminal) get a width that fits the KPI table on one line per service.
console = Console(stderr=True, width=None if sys.stderr.isatty() else 120)
#: Monument of UNAVCO station USLO (RINEX header comment), truth for the embedded demo data.
USLO_REFERENCE = "35.311803,-120.661092,134.6419"
DEMO_POS = "uslo-2006-361-waas.pos.gz"


@contextlib.contextmanager
def _progress() -> Iterator[Progress]:
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=not console.is_terminal,
    ) as bar:
        yield bar


def _draws_figures(command=None, *, defer: Callable[[dict], bool] | None = None):
    """Run ``command`` with its report figures drawn by worker processes
    (:func:`overbound.report.rendering.parallel_figures`; ``OVERBOUND_FIGURE_PROCESSES`` sets how many),
    started at once unless ``defer(the command's arguments)`` says to start them at the first figure."""

    def decorate(command):
        @functools.wraps(command)
        def wrapper(*args, **kwargs):
            from overbound.report.rendering import parallel_figures

            with parallel_figures(start=not (defer and defer(kwargs))):
                return command(*args, **kwargs)

        return wrapper

    return decorate(command) if command is not None else decorate


def _is_campaign(kwargs: dict) -> bool:
    """Whether ``analyze`` was given one campaign dataset: minutes of work on Dask workers that need the
    memory the figure processes would hold idle (about 160 MB each), and whose report is a small share."""
    inputs = kwargs.get("inputs") or ()
    return len(inputs) == 1 and is_dataset(inputs[0])


@contextlib.contextmanager
def _staged(out_dir: Path, command: str) -> Iterator[StagedDirectory]:
    """The command's output directory, written whole or not at all (:mod:`overbound.output`);
    says which files of an earlier run it removed and which others it kept."""
    with staged_directory(out_dir, command=command) as stage:
        yield stage
    if stage.removed:
        console.print(f"removed, written by an earlier {command} but not by this one: "
                      + ", ".join(stage.removed), highlight=False, soft_wrap=True)  # fmt: skip
    if stage.kept:
        console.print(f"kept in {out_dir}, not written by this {command}: " + ", ".join(stage.kept),
                      highlight=False, soft_wrap=True)  # fmt: skip


def _reference(lla: str | None, ecef: str | None) -> Reference | MeanPosition | None:
    if lla and ecef:
        raise click.UsageError("give --reference or --reference-ecef, not both")
    if lla is not None and lla.strip().lower() == "mean":
        return MEAN_POSITION
    try:
        if lla:
            return Reference.parse(lla)
        if ecef:
            return Reference.parse_ecef(ecef)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None
    return None


def _truth(path: Path, max_gap: float | None, quality: str | None, interpolation: str, strict: bool):
    """The --truth trajectory (:func:`overbound.io.truth.read_truth`)."""
    from overbound.io.truth import read_truth

    flags = None
    if quality is not None:
        try:
            flags = tuple(int(q) for q in quality.split(","))
        except ValueError:
            raise click.BadParameter(f"{quality!r}: expected Q flags, e.g. 1 or 1,2") from None
    return read_truth(path, max_gap_s=max_gap, quality=flags, interpolation=interpolation, strict=strict)


class _Group(click.Group):
    """Turns input errors into one clean line and exit status 2."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.exceptions.Abort):  # RuntimeErrors since click 8.2: --help,
            raise  # --version, Ctrl-C are not input errors
        except (InputError, OutputError) as exc:
            _fail(str(exc))
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            from overbound.analysis import error_text

            _fail(error_text(exc))


def _fail(message: str) -> None:
    console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    sys.exit(2)


@click.group(cls=_Group)
@click.version_option(__version__, prog_name="overbound")
def main() -> None:
    """GNSS integrity verification: availability, continuity, Stanford diagrams and MI statistics."""


class _Instant(click.ParamType):
    """An ISO 8601 time for --start/--end: date, ``T`` or a space, seconds with a fraction or none; a
    trailing ``Z`` or a UTC offset (``+02:00``) makes it UTC whatever --time-scale says. Converted to
    ``(naive datetime, is_utc)``; :func:`_gps_time` turns it into GPS time."""

    name = "time"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        text = str(value).strip()
        zulu = text[-1:] in ("Z", "z")
        try:
            t = datetime.datetime.fromisoformat(text[:-1] if zulu else text)
        except ValueError:
            self.fail(
                f"{value!r}: expected an ISO 8601 time, e.g. 2024-01-07T06:00:00 or 2024-01-07 06:00:00Z"
            )
        if t.tzinfo is not None:
            return t.astimezone(datetime.UTC).replace(tzinfo=None), True
        return t, zulu


def _gps_time(value: tuple[datetime.datetime, bool] | None, scale: str) -> datetime.datetime | None:
    """GPS time of a --start/--end value: a UTC one (``Z``, an offset, or ``--time-scale utc``) plus the
    GPS-UTC leap seconds in force then (:data:`overbound.io.gpstime.GPS_UTC_LEAP_SECONDS`)."""
    if value is None:
        return None
    t, utc = value
    if utc or scale == "utc":
        from overbound.io.gpstime import gps_utc_offset

        return t + datetime.timedelta(seconds=gps_utc_offset(t))
    return t


_input_options = [
    click.option(
        "--reference",
        "reference",
        metavar="LAT,LON,H|mean",
        help="True antenna position, geodetic WGS-84 (deg, deg, ellipsoidal m), e.g. "
        "35.3118,-120.6611,134.64; 'mean': a static receiver without a surveyed position, errors against "
        "the mean of its own positions (the report says so first).",
    ),
    click.option(
        "--reference-ecef", "reference_ecef", metavar="X,Y,Z", help="True antenna position, ECEF (m)."
    ),
    click.option(
        "--truth",
        "truth",
        type=click.Path(dir_okay=False, path_type=Path),
        metavar="FILE",
        help="Truth trajectory of a moving receiver, instead of --reference: an RTKLIB .pos (e.g. a "
        "post-processed RTK/PPK solution; lat/lon/height or x/y/z-ecef, GPST or UTC) or a CSV with "
        "time (ISO GPS time), gps_seconds or week,tow and lat,lon,height or x,y,z (ECEF m). Interpolated "
        "to each epoch; errors in the east-north-up frame of the truth there. Epochs outside its span are "
        "rejected, epochs in its gaps become no-solution epochs (counted); the report says what the errors "
        "rest on.",
    ),
    click.option(
        "--truth-max-gap",
        "truth_max_gap",
        type=click.FloatRange(min=0, min_open=True),
        metavar="S",
        help="With --truth: an epoch between truth samples more than S seconds apart has no truth "
        "(default: 1.5 x the truth's median interval).",
    ),
    click.option(
        "--truth-quality",
        "truth_quality",
        metavar="Q[,Q...]",
        help="With an RTKLIB .pos --truth: the Q flags kept, e.g. 1 (fixed only) or 1,2 (default: all but "
        "0, no solution); the others make gaps.",
    ),
    click.option(
        "--truth-interpolation",
        "truth_interpolation",
        type=click.Choice(["cubic", "linear"]),
        default="cubic",
        show_default=True,
        help="With --truth: a cubic spline per ECEF coordinate (0.5 mm in a 30-degree banked turn at "
        "70 m/s and 1 Hz) or linear (0.7 m there, adequate at 10 Hz or in straight lines).",
    ),
    click.option(
        "--format", "fmt", type=click.Choice(FORMATS), help="Force the input format (default: detect)."
    ),
    click.option(
        "--station",
        help="Station name where the input names none (an input's own station name wins, with a note).",
    ),
    click.option("--strict", is_flag=True, help="Stop at the first malformed row instead of counting it."),
    click.option(
        "--start",
        type=_Instant(),
        metavar="TIME",
        help="Keep epochs from this time on: ISO 8601, GPS time unless --time-scale utc, a trailing Z or an "
        "offset, e.g. 2024-01-07T06:00:00, '2024-01-07 06:00:00Z', 2024-01-07T08:00:00+02:00.",
    ),
    click.option("--end", type=_Instant(), metavar="TIME", help="Keep epochs before this time (as --start)."),
    click.option(
        "--time-scale",
        "time_scale",
        type=click.Choice(["gps", "utc"]),
        default="gps",
        show_default=True,
        help="Time scale of --start/--end without Z or offset; UTC is converted to GPS time with the "
        "leap seconds in force then.",
    ),
    click.option(
        "--column",
        "column_map",
        multiple=True,
        metavar="NAME=COLUMN",
        help="CSV/Parquet: epoch-table column NAME is COLUMN of the file (repeatable), e.g. vpl=VPL_m.",
    ),
]


def _output_dir(help_text: str):
    """The ``-o/--output`` directory option of the analysis commands."""
    return click.option(
        "-o",
        "--output",
        "out_dir",
        required=True,
        type=click.Path(file_okay=False, path_type=Path),
        help=help_text,
    )


_services_option = click.option(
    "--service",
    "services",
    multiple=True,
    metavar="NAME|NAME:HAL:VAL",
    help="Service level (repeatable); default: all of NPA, APV-I, APV-II, LPV, LPV-200, CAT-I.",
)


def _with_input_options(f):
    for opt in reversed(_input_options):
        f = opt(f)
    return f


def _read_options(
    reference,
    reference_ecef,
    fmt,
    station,
    strict,
    start,
    end,
    column_map,
    time_scale="gps",
    truth=None,
    truth_max_gap=None,
    truth_quality=None,
    truth_interpolation="cubic",
) -> dict:
    """Keyword arguments of :func:`overbound.io.read` from the shared input options."""
    mapping = {}
    for item in column_map:
        name, sep, col = item.partition("=")
        if not sep or not name or not col:
            raise click.BadParameter(f"{item!r}: expected NAME=COLUMN", param_hint="--column")
        mapping[name.strip()] = col.strip()
    ref = _reference(reference, reference_ecef)
    if truth is not None:
        if ref is not None:
            raise click.UsageError("give --truth or --reference/--reference-ecef, not both")
        ref = _truth(truth, truth_max_gap, truth_quality, truth_interpolation, strict)
    elif truth_max_gap is not None or truth_quality is not None:
        raise click.UsageError("--truth-max-gap and --truth-quality apply with --truth")
    return {
        "reference": ref,
        "format": fmt,
        "station": station,
        "strict": strict,
        "mapping": mapping or None,
        "time_range": (_gps_time(start, time_scale), _gps_time(end, time_scale)) if start or end else None,
    }


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@_output_dir("Output directory for summary.json and report.html.")
@_services_option
@_with_input_options
@click.option(
    "--epochs",
    "epochs_out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the pooled epoch table (.parquet or .csv).",
)
@click.option(
    "--confidence/--no-confidence",
    default=True,
    show_default=True,
    help="Add the PL confidence level per PL band (vertical; horizontal too with east/north errors).",
)
@click.option(
    "--evt/--no-evt",
    default=True,
    show_default=True,
    help="Add the EVT tail extrapolation of P_MI and P_HMI (vertical; horizontal too with HPL): "
    "OUTPUT/evt-<axis>.json.",
)
@click.option(
    "--parametric/--no-parametric",
    default=True,
    show_default=True,
    help="Add the parametric availability, integrity and continuity (Kannemans 2006) of both axes: "
    "OUTPUT/parametric.json.",
)
@click.option(
    "--counting-only",
    is_flag=True,
    help="Campaign dataset: the counting KPIs and network results only, without reading the pooled "
    "table (no methods, no verdicts).",
)
@click.option(
    "--workers",
    type=click.IntRange(min=0),
    metavar="N",
    help="Campaign dataset: N local worker processes (0: this process). Default: this process for a "
    "dataset under 64 MiB or whose partials are cached but for a few station-days, else one worker "
    "per core.",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    envvar="DASK_SCHEDULER_ADDRESS",
    help="Campaign dataset: run on the Dask cluster at ADDRESS (e.g. tcp://host:8786; default "
    "$DASK_SCHEDULER_ADDRESS, which --workers overrides); the dataset must be at the same absolute "
    "path on its workers.",
)
@click.option(
    "--cache/--no-cache",
    default=True,
    show_default=True,
    help="Campaign dataset: keep partial results per station-day beside the data, and reuse them.",
)
@_draws_figures(defer=_is_campaign)
def analyze(
    inputs,
    out_dir,
    services,
    epochs_out,
    confidence,
    evt,
    parametric,
    counting_only,
    workers,
    scheduler,
    cache,
    **inputs_opts,
) -> None:
    """Analyse receiver output INPUTS, or a campaign dataset: write OUTPUT/summary.json and
    OUTPUT/report.html.

    A dataset (see 'overbound ingest') is counted station-day by station-day, on Dask workers
    when it is large, with partial results cached beside the data.
    """
    read_options = _read_options(**inputs_opts)
    campaign = _is_campaign({"inputs": inputs})
    given = _given_options(click.get_current_context())
    if not campaign and (counting_only or given & {"--workers", "--scheduler"}):
        raise click.UsageError("--counting-only, --workers and --scheduler apply to a campaign dataset")
    if campaign:  # the workers open the partitions by this path: not relative to their own folder
        workers, scheduler = _cluster_choice(workers, scheduler)
        inputs = (inputs[0].resolve(),)
    if campaign and epochs_out:
        raise click.UsageError(
            "--epochs writes the pooled epoch table, which a dataset's analysis does not read "
            "(its partitions are the epoch table)"
        )
    with contextlib.ExitStack() as outputs:  # both checked (and locked) before the analysis
        stage = outputs.enter_context(_staged(out_dir, "analyze"))
        epochs_path = _epochs_path(epochs_out, stage, outputs) if epochs_out else None
        small = functools.partial(_small_campaign, inputs[0], services, read_options["time_range"], cache)
        client = (
            outputs.enter_context(_campaign_client(inputs[0], workers, scheduler, small))
            if campaign
            else None
        )
        paths = _run_analysis(
            list(inputs),
            stage.path,
            services=services,
            epochs_out=epochs_path,
            confidence=confidence and not counting_only,
            evt=evt and not counting_only,
            parametric=parametric and not counting_only,
            campaign={"client": client, "counting_only": counting_only, "cache": cache} if campaign else {},
            **read_options,
        )
    click.echo(f"report: {stage.final(paths[1])}")
    click.echo(f"summary: {stage.final(paths[0])}")


#: A dataset smaller than this is counted in this process (a cluster costs seconds to start).
_IN_PROCESS_BYTES = 64 << 20
#: A dataset whose partials are cached but for this many partitions is counted in this process.
_IN_PROCESS_UNCACHED = 64


def _cluster_choice(workers: int | None, scheduler: str | None) -> tuple[int | None, str | None]:
    """``--workers`` (local workers) or ``--scheduler`` (a running cluster), not both; an explicit
    ``--workers`` wins over ``$DASK_SCHEDULER_ADDRESS`` (an option given beats the environment)."""
    if workers is None or not scheduler:
        return workers, scheduler
    if "--scheduler" not in _given_options(click.get_current_context()):  # from the environment
        return workers, None
    raise click.UsageError("--workers starts local workers, --scheduler uses a running cluster: give one")


@contextlib.contextmanager
def _campaign_client(dataset: Path, workers: int | None, scheduler: str | None, in_process):
    """The Dask client of a campaign analysis (``None``: in this process); closed at the end.
    ``in_process()`` says whether the work left is small enough not to start a cluster."""
    from overbound.campaign import campaign_client

    if not scheduler:
        if workers == 0:
            yield None
            return
        if workers is None and in_process():
            yield None
            return
    client = campaign_client(workers=workers, scheduler=scheduler)
    try:
        yield client
    finally:
        cluster = client.cluster
        client.close()
        if cluster is not None:
            cluster.close()


def _small_campaign(dataset: Path, services, time_range, cache: bool) -> bool:
    """Under 64 MiB of partitions, or (with the cache) under 64 partitions not cached: a cluster
    would take longer to start than the work."""
    from overbound.campaign import uncached_partitions
    from overbound.io.dataset import partitions
    from overbound.services import resolve_services

    if sum(p.path.stat().st_size for p in partitions(dataset)) < _IN_PROCESS_BYTES:
        return True
    levels = resolve_services(list(services) or None)
    return cache and uncached_partitions(dataset, levels, time_range=time_range) <= _IN_PROCESS_UNCACHED


def _epochs_path(epochs_out: Path, stage: StagedDirectory, outputs: contextlib.ExitStack) -> Path:
    """Where ``--epochs`` is written: in the staging directory when it lies in the output
    directory (it is then one of the run's files), else through its own staged file."""
    real = Path(os.path.realpath(epochs_out))
    if real.is_relative_to(stage.target):
        return stage.path / real.relative_to(stage.target)
    return outputs.enter_context(staged_files(epochs_out))


def _run_analysis(
    inputs,
    out_dir: Path,
    *,
    services=(),
    epochs_out=None,
    title=None,
    confidence=True,
    evt=True,
    parametric=True,
    campaign=None,
    **read_opts,
):
    """Analyse, write summary.json and report.html (and the epoch table); return their paths.
    ``campaign``: the campaign options of :func:`overbound.analysis.analyze` for a dataset."""
    from overbound.analysis import analyze as run
    from overbound.io.table import write_epochs
    from overbound.jsontext import dumps
    from overbound.methods.parametric import write_parametric
    from overbound.methods.tail_extrapolation import write_evt
    from overbound.report.confidence import json_name, write_confidence
    from overbound.report.evt import json_name as evt_json_name
    from overbound.report.html import write_report
    from overbound.report.json import provenance_dict, summary_dict
    from overbound.report.parametric import JSON_NAME as PARAMETRIC_JSON
    from overbound.verdict import assess

    if epochs_out:
        columns = None  # the epoch table written keeps every column
    else:
        alert = confidence or evt or parametric
        columns = (("east", "north") if confidence else ()) + (("alert",) if alert else ())
    with _progress() as bar:
        task = bar.add_task("reading", total=len(inputs) + 4 + 2 * evt + parametric)

        def step(what: str) -> None:
            bar.update(task, description=f"{what}", advance=1)

        result = run(
            inputs,
            services=list(services) or None,
            title=title,
            **read_opts,
            columns=columns,
            confidence=None if confidence else (),
            evt=None if evt else (),
            parametric=parametric,
            progress=step,
            **(campaign or {}),
        )
        out_dir.mkdir(parents=True, exist_ok=True)  # a demo's subdirectory
        if result.pl_only is not None:
            if epochs_out:
                from overbound.io.dataset import NO_TRUTH_TABLE

                raise InputError(
                    ", ".join(r.source for r in result.reports), NO_TRUTH_TABLE + " (no --epochs)"
                )
            return _write_pl_only(result, out_dir, inputs, read_opts, step)
        for c in result.confidence:
            write_confidence(c, out_dir / json_name(c.axis))
        for e in result.evt:
            write_evt(e, out_dir / evt_json_name(e.axis))
        if result.parametric is not None:
            write_parametric(result.parametric, out_dir / PARAMETRIC_JSON)
        step("writing summary.json")
        assessment = assess(result) if result.evidence is not None else None
        options = {
            "services": list(services),
            "confidence": confidence,
            "evt": evt,
            "parametric": parametric,
            **{k: v for k, v in read_opts.items() if v is not None},
        }
        command = ["overbound", *sys.argv[1:]]
        doc = summary_dict(
            result, assessment=assessment, provenance=provenance_dict(inputs, command, options)
        )
        summary = out_dir / "summary.json"
        summary.write_text(dumps(doc), encoding="utf-8")
        step("drawing report.html")
        report = write_report(result, out_dir, summary=doc, assessment=assessment)
        if epochs_out:
            epochs_out.parent.mkdir(parents=True, exist_ok=True)
            write_epochs(result.table, epochs_out)
    _print_summary(result, assessment)
    return summary, report, assessment


def _with_truth(table, reports):
    """``table``, or an :class:`InputError` when an input has no truth: the methods need errors."""
    if any(not r.truth for r in reports):
        from overbound.methods.protection_levels import NO_TRUTH

        source = ", ".join(r.source for r in reports if not r.truth)
        why = "this method needs them ('overbound analyze' gives what the protection levels alone give)"
        raise InputError(source, f"{NO_TRUTH}: {why}")
    return table


def _write_pl_only(result, out_dir: Path, inputs, read_opts: dict, step):
    """summary.json and report.html of inputs without truth (:mod:`overbound.report.pl_only`)."""
    from overbound.jsontext import dumps
    from overbound.report.json import provenance_dict
    from overbound.report.pl_only import pl_only_dict, write_pl_only_report

    step("writing summary.json")
    options = {k: v for k, v in read_opts.items() if v is not None}
    doc = pl_only_dict(result, provenance_dict(inputs, ["overbound", *sys.argv[1:]], options))
    summary = out_dir / "summary.json"
    summary.write_text(dumps(doc), encoding="utf-8")
    step("drawing report.html")
    report = write_pl_only_report(result, out_dir / "report.html", doc)
    e = doc["epochs"]
    console.print(
        f"[bold]{result.title}[/]: {e['total']} epochs, {e['with_pl']} with protection levels, "
        f"{e['rejected']} rejected",
        highlight=False,
        soft_wrap=True,
    )
    for w in result.warnings:
        console.print(f"[bold yellow]warning:[/] {w}", highlight=False, soft_wrap=True)
    t = Table("flight", "epochs", "with PL", "HPL 95 %", "VPL 95 %", *doc["services"])
    for name, st in doc["stations"].items():
        avail = [_fmt(st["services"][s]["availability"]["combined"], True) for s in doc["services"]]
        pls = (_fmt_m(st["hpl"]["p95"]), _fmt_m(st["vpl"]["p95"]))
        t.add_row(name, str(st["epochs"]), str(st["with_pl"]), *pls, *avail)
    console.print(t)
    return summary, report, None


def _fmt_m(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1f} m"


def _fmt(x: float | None, pct: bool = False) -> str:
    """A share as a percentage, or a probability (``< 1e-15`` below that, :mod:`overbound.numbers`)."""
    from overbound.numbers import format_probability

    if x is None:
        return "n/a"
    return f"{100 * x:.3f} %" if pct else format_probability(x)


def _print_summary(result, assessment) -> None:
    c = result.counting
    rejected = sum(r.n_rejected for r in result.reports)
    console.print(
        f"[bold]{result.title}[/]: {c.n_total} epochs, {c.n_with_solution} with solution, "
        f"{rejected} rejected; "
        f"HPE95 {_fmt(c.hpe95)} m, |VPE|95 {_fmt(c.vpe95)} m",
        highlight=False,
    )
    if result.truth:
        console.print(result.truth["statement"], highlight=False, soft_wrap=True)
    for w in result.warnings:
        console.print(f"[bold yellow]warning:[/] {w}", highlight=False, soft_wrap=True)
    t = Table(
        "service", "HAL/VAL", "avail. H", "avail. V", "avail. H+V", "cont. risk H+V", "MI H/V", "HMI H/V"
    )
    for name, k in c.services.items():
        s = k.service
        v = k.vertical.stanford
        t.add_row(
            name,
            f"{s.hal:g}/{'-' if s.val is None else f'{s.val:g}'}",
            _fmt(k.horizontal.availability, True),
            _fmt(k.vertical.availability, True),
            _fmt(k.combined.availability, True),
            _fmt(k.combined.continuity.risk if k.combined.continuity else None),
            f"{k.horizontal.stanford.mi}/{v.mi if v else '-'}",
            f"{k.horizontal.stanford.hmi}/{v.hmi if v else '-'}",
        )
    console.print(t)
    if result.network is not None:
        net = result.network
        console.print(
            f"dataset: {net.n_partitions - len(net.failures)} of {net.n_partitions} station-days analysed; "
            f"partial results {net.n_cached} from the cache, {net.n_computed} computed",
            highlight=False,
        )
        for f in net.failures:
            console.print(f"unreadable, left out: {f.station} {f.date}: {f.reason}", highlight=False)
    for axis, reason in result.evt_failures:
        console.print(f"EVT {axis}: no estimate: {reason}", highlight=False, soft_wrap=True)
    for method, axis, reason in result.method_failures:
        console.print(f"{method} {axis}: not computed: {reason}", highlight=False, soft_wrap=True)
    if result.parametric is not None:
        for axis, reason in result.parametric.reasons.items():
            console.print(f"parametric {axis}: no estimate: {reason}", highlight=False, soft_wrap=True)
    _print_verdicts(assessment)


_VERDICT_STYLE = {"pass": "bold green", "fail": "bold red", "not demonstrated": "bold yellow"}


def _print_verdicts(assessment) -> None:
    """The verdict matrix, then one line per verdict that is not a pass."""
    if assessment is None:
        console.print("verdicts: not assessed (counting only)", highlight=False)
        return
    from overbound.report.verdicts import KIND_TITLES
    from overbound.verdict import KINDS

    kinds = (*KINDS, "overall")
    t = Table("service", *(KIND_TITLES[k] for k in kinds), title="Verdicts")
    for name, sv in assessment.services.items():
        t.add_row(name, *(f"[{_VERDICT_STYLE[sv.get(k).verdict]}]{sv.get(k).verdict}[/]" for k in kinds))
    console.print(t)
    for st, per in assessment.by_station.items():
        line = ", ".join(f"{name} {sv.overall.verdict}" for name, sv in per.items())
        console.print(f"station {st}: {line}", highlight=False, soft_wrap=True)
    for name, sv in assessment.services.items():
        for k in KINDS:
            v = sv.get(k)
            if v.verdict != "pass":
                console.print(
                    f"{name} {k.replace('_', ' ')}: {v.verdict}: {v.sentence}",
                    highlight=False,
                    soft_wrap=True,
                )


_VERDICT_KEYS = ("integrity", "availability", "continuity")


def _parametric_lines(analysis) -> list[str]:
    """One line per axis: P_MI, its bound and each service's integrity/availability/continuity verdicts."""
    from overbound.report.parametric import service_verdicts
    from overbound.report.parametric_figures import format_probability as fp

    word = {True: "ok", False: "FAIL", None: "n.a."}
    levels = {s.name: s for s in analysis.services}
    lines = []
    for axis in ("vertical", "horizontal"):
        a = analysis.axis(axis)
        if a is None:
            lines.append(f"parametric {axis}: no estimate: {analysis.reasons.get(axis, 'not analysed')}")
            continue
        verdicts = []
        for name, s in a.services.items():
            if s is not None:
                v = service_verdicts(a, levels[name])
                verdicts.append(f"{name} " + "/".join(word[v[k]] for k in _VERDICT_KEYS))
        lines.append(
            f"parametric {axis}: P_MI {fp(a.p_mi, a.log10_p_mi)} per epoch, bound "
            f"{fp(a.p_mi_bound, a.log10_p_mi_bound)}; integrity/availability/continuity: "
            + (", ".join(verdicts) or "no service")
        )
    return lines


def _evt_line(a) -> str:
    """One line of an EVT result: P_MI, its interval and bounds, and each service's verdict."""
    t = a.tail
    verdict = {True: "meets", False: "does not meet", None: "no estimate"}
    services = ", ".join(f"{n} {verdict[h.meets_requirement]}" for n, h in a.services.items()) or "none"
    return (
        f"EVT {a.axis}: P_MI {_fmt(t.p)} per epoch [{_fmt(t.p_ci[0])}, {_fmt(t.p_ci[1])}], "
        f"P_MI95 {_fmt(t.p_95)}; per approach upper bound {_fmt(t.p_approach_95)}; "
        f"HMI requirement: {services}"
    )


@main.command()
@click.option(
    "-o",
    "--output",
    "out",
    required=True,
    type=click.Path(path_type=Path),
    help="Output epoch table (.parquet or .csv), or a campaign dataset directory (any other name), "
    "written one station-day at a time.",
)
@click.option(
    "--days",
    default=7.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Days simulated per station (1 Hz unless --interval).",
)
@click.option(
    "--seed", default=0, show_default=True, type=int, help="Seed of every random draw (same seed, same data)."
)
@click.option(
    "--interval",
    "interval_s",
    default=1.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Sampling interval (s).",
)
@click.option(
    "--stations",
    default=1,
    show_default=True,
    type=click.IntRange(min=1),
    help="Stations simulated (independent errors, names SIM01, SIM02, ...).",
)
@click.option(
    "--sigma-ratio",
    default=None,
    type=float,
    help="Error sigma relative to PL/K: <1 overbounded, >1 violated.",
)
@click.option("--correlation", "correlation_s", default=None, type=float, help="Error correlation time (s).")
@click.option("--tail-fraction", default=None, type=float, help="Share of epochs in the heavy-tail regime.")
@click.option(
    "--tail-scale", default=None, type=float, help="Error sigma multiplier in the heavy-tail regime."
)
@click.option(
    "--anomaly",
    "anomalies",
    multiple=True,
    metavar="band:LO:HI:FACTOR[:AXIS] | bias:START_H:DURATION_S:METRES[:AXIS] | outage:START_H:DURATION_S",
    help="Inject an anomaly (repeatable).",
)
def simulate(
    out, days, seed, interval_s, stations, sigma_ratio, correlation_s, tail_fraction, tail_scale, anomalies
) -> None:
    """Simulate a receiver campaign with known truth and write its epoch table."""
    from overbound.simulate import SimulationConfig, parse_anomaly, write_simulation
    from overbound.simulate import simulate as run

    options = {
        "sigma_ratio": sigma_ratio,
        "correlation_s": correlation_s,
        "tail_fraction": tail_fraction,
        "tail_scale": tail_scale,
    }
    config = SimulationConfig(
        days=days,
        seed=seed,
        interval_s=interval_s,
        stations=stations,
        anomalies=tuple(parse_anomaly(a) for a in anomalies),
        **{k: v for k, v in options.items() if v is not None},
    )
    if out.suffix.lower() not in (".parquet", ".pq", ".csv"):
        from overbound.simulate import write_simulation_dataset

        with _progress() as bar:
            bar.add_task(f"simulating {stations} x {days:g} days into {out}", total=None)
            parts = write_simulation_dataset(config, out)
        click.echo(f"{out}: {len(parts)} station-days of {stations} stations (dataset)")
        return
    with staged_files(out) as staged, _progress() as bar:
        bar.add_task(f"simulating {days:g} days", total=None)
        sim = run(config)
        write_simulation(sim, staged)
    click.echo(
        f"{out}: {sim.table.height} epochs; true P(|VPE|>VPL) per epoch {sim.p_mi_true('vertical'):.3e}, "
        f"true P(HPE>HPL) {sim.p_mi_true('horizontal'):.3e}"
    )


@main.command()
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@_with_input_options
def ingest(dataset, inputs, **inputs_opts) -> None:
    """Add INPUTS (any supported format) to the campaign DATASET, split by station and GPS day.

    DATASET is a directory (created when new) of Parquet partitions
    station=ID/date=YYYY-MM-DD/part-0.parquet with a manifest, dataset.json; analyse it with
    `overbound analyze DATASET -o OUT`. A station-day already there is replaced, and said so.
    """
    from overbound.io.dataset import ingest as run

    result = run(dataset, list(inputs), **_read_options(**inputs_opts))
    for r in result.reports:
        console.print(f"{r.source}: {_read_line(r)}", highlight=False, soft_wrap=True)
        for note in r.notes:
            if note.startswith("station argument"):  # the partitions are named otherwise than asked
                console.print(f"{r.source}: {note}", highlight=False, soft_wrap=True)
    replaced = set(result.replaced)
    for p in result.written:
        note = " (replaced)" if p.key in replaced else ""
        click.echo(f"{dataset / p.key}: {result.rows[p.key]} epochs{note}")


@main.command()
@click.argument("source", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    "out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Epoch table to write (.parquet or .csv).",
)
@_with_input_options
def convert(source, out, **inputs_opts) -> None:
    """Read SOURCE in any supported format and write it as an epoch table."""
    from overbound.io.open import read
    from overbound.io.table import write_epochs

    read_options = _read_options(**inputs_opts)
    with staged_files(out) as staged:
        table, report = read(source, **read_options)
        if not report.truth:
            from overbound.io.dataset import NO_TRUTH_TABLE

            raise InputError(report.source, NO_TRUTH_TABLE)
        write_epochs(table, staged, report=report)
    click.echo(f"{out}: {_read_line(report)}")


def _read_line(r) -> str:
    """What a reader did, on one line: epochs kept of rows read, rejected and invalidated by reason."""
    return (
        f"{r.rows_kept} epochs from {r.rows_read} rows ({r.format}); "
        f"rejected {r.n_rejected} {dict(sorted(r.rejected.items()))}; "
        f"invalidated {sum(r.invalidated.values())} {dict(sorted(r.invalidated.items()))}"
    )


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@_output_dir("Output directory for confidence.json and confidence.html.")
@click.option(
    "--axis",
    type=click.Choice(["vertical", "horizontal"]),
    default="vertical",
    show_default=True,
    help="PL to assess; horizontal needs signed east/north errors.",
)
@click.option(
    "--min-samples",
    default=200,
    show_default=True,
    type=click.IntRange(min=2),
    help="Independent samples a PL band needs (Comby et al. 2003: 200).",
)
@click.option(
    "--spacing",
    default=360.0,
    show_default=True,
    type=click.FloatRange(min=0),
    help="Seconds between independent samples.",
)
@click.option(
    "--tolerance",
    default=0.125,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Band half-width (m).",
)
@click.option(
    "--max-tolerance",
    default=1.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Widest band half-width when a band is widened to reach --min-samples (m).",
)
@click.option(
    "--step",
    default=0.25,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Target step (m).",
)
@click.option(
    "--max-pl",
    default=50.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Last target (m).",
)
@click.option(
    "--risk",
    default=1e-7,
    show_default=True,
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    help="Integrity risk per independent sample.",
)
@_with_input_options
@_draws_figures(defer=_is_campaign)
def confidence(
    inputs, out_dir, axis, min_samples, spacing, tolerance, max_tolerance, step, max_pl, risk, **inputs_opts
) -> None:
    """PL confidence level per PL band (Comby et al. 2003): OUTPUT/confidence.json and confidence.html."""
    from overbound.analysis import load_epochs
    from overbound.report.confidence import run_confidence

    read_options = _read_options(**inputs_opts)
    with _staged(out_dir, "confidence") as stage, _progress() as bar:
        bar.add_task(f"{axis} PL confidence level", total=None)
        table = _with_truth(*load_epochs(list(inputs), columns=("east", "north", "alert"), **read_options))
        run = run_confidence(
            table,
            stage.path,
            axes=(axis,),
            min_samples=min_samples,
            spacing=spacing,
            tolerance=tolerance,
            max_tolerance=max_tolerance,
            step=step,
            max_pl=max_pl,
            risk=risk,
        )
    (a,), (path,) = run.analyses, run.json_paths
    with_cl = [b for b in a.bins if b.sufficient]
    suspect = ", ".join(f"{a.bins[i].target:.2f}" for i in a.suspect) or "none"
    console.print(
        f"{a.axis}: {len(a.bins)} bands, {len(with_cl)} with {a.min_samples} samples; "
        f"confidence below 1 % at PL {suspect}",
        highlight=False,
        soft_wrap=True,
    )
    click.echo(f"confidence: {stage.final(path)}")
    click.echo(f"report: {stage.final(run.report)}")


def _auto_or_float(*, below: float | None = None, minimum: float | None = None):
    """A click callback: ``auto`` or a finite number (below ``below``, at least ``minimum``).

    A bad value is a usage error naming the option (exit status 2).
    """

    def convert(ctx, param, value: str) -> str | float:
        if value.strip().lower() == "auto":
            return "auto"
        try:
            x = float(value)
        except ValueError:
            raise click.BadParameter(f"{value!r}: expected 'auto' or a number") from None
        if (
            not math.isfinite(x)
            or (below is not None and x >= below)
            or (minimum is not None and x < minimum)
        ):
            bounds = f" below {below:g}" if below is not None else ""
            bounds += f" at least {minimum:g}" if minimum is not None else ""
            raise click.BadParameter(f"{value!r}: expected 'auto' or a finite number{bounds}")
        return x

    return convert


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@_output_dir("Output directory for evt.json and evt.html.")
@click.option(
    "--axis",
    type=click.Choice(["vertical", "horizontal"]),
    default="vertical",
    show_default=True,
    help="Safety index to extrapolate: |VPE|/VPL or HPE/HPL.",
)
@click.option(
    "--service",
    metavar="NAME|NAME:HAL:VAL",
    help="HMI filtering: drop epochs with PL >= AL and those in the TTA before an alert "
    "(default: none); the HMI result is then given for this service only.",
)
@click.option(
    "--threshold",
    default="auto",
    show_default=True,
    metavar="auto|VALUE",
    callback=_auto_or_float(below=1.0),
    help="Tail threshold of the safety index (below 1), or automatic (Anderson-Darling + ForwardStop).",
)
@click.option(
    "--cluster-gap",
    default="auto",
    show_default=True,
    metavar="auto|SECONDS",
    callback=_auto_or_float(minimum=0.0),
    help="Gap K_T between clusters of exceedances (s), or read from the V_K curve.",
)
@click.option(
    "--decluster/--no-decluster",
    default=True,
    show_default=True,
    help="Fit the GPD to cluster maxima, or to all exceedances.",
)
@click.option(
    "--bootstrap",
    "n_boot",
    default=1000,
    show_default=True,
    type=click.IntRange(min=1),
    help="Bootstrap resamples for the intervals.",
)
@click.option(
    "--confidence",
    default=0.95,
    show_default=True,
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    help="Level of the intervals and one-sided upper bounds.",
)
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the bootstrap.")
@_with_input_options
@_draws_figures(defer=_is_campaign)
def evt(
    inputs, out_dir, axis, service, threshold, cluster_gap, decluster, n_boot, confidence, seed, **inputs_opts
) -> None:
    """P_MI and P_HMI by EVT tail extrapolation (Veerman et al., GIMAT): OUTPUT/evt.json and evt.html."""
    from overbound.analysis import load_epochs
    from overbound.report.evt import run_evt

    read_options = _read_options(**inputs_opts)
    with _staged(out_dir, "evt") as stage, _progress() as bar:
        bar.add_task(f"{axis} EVT tail extrapolation", total=None)
        table = _with_truth(*load_epochs(list(inputs), columns=("alert",), **read_options))
        run = run_evt(
            table,
            stage.path,
            axis=axis,
            service=service,
            threshold=threshold,
            cluster_gap=cluster_gap,
            decluster=decluster,
            n_boot=n_boot,
            confidence=confidence,
            seed=seed,
        )
    console.print(_evt_line(run.analysis), highlight=False, soft_wrap=True)
    click.echo(f"evt: {stage.final(run.json_path)}")
    click.echo(f"report: {stage.final(run.report)}")


def _decorrelation_option(ctx, param, value: str) -> str | float:
    """``auto`` or seconds > 0 (a click callback; a bad value is a usage error naming the option)."""
    x = _auto_or_float()(ctx, param, value)
    if x != "auto" and not x > 0:
        raise click.BadParameter(f"{value!r}: expected 'auto' or a finite number of seconds above 0")
    return x


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@_output_dir("Output directory for parametric.json and parametric.html.")
@_services_option
@click.option(
    "--decorrelation",
    default="auto",
    show_default=True,
    metavar="auto|SECONDS",
    callback=_decorrelation_option,
    help="Decorrelation time of the ratio and of the PL (s), or read from each ACF (first lag below 1/e).",
)
@click.option(
    "--confidence",
    default=0.95,
    show_default=True,
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    help="One-sided confidence level of the bounds.",
)
@_with_input_options
@_draws_figures(defer=_is_campaign)
def parametric(inputs, out_dir, services, decorrelation, confidence, **inputs_opts) -> None:
    """Parametric integrity, availability and continuity (Kannemans 2006): OUTPUT/parametric.json, .html.

    A dataset (see 'overbound ingest') is analysed partition by partition, in this process.
    """
    from overbound.analysis import load_epochs
    from overbound.report.parametric import run_parametric, write_parametric_run

    read_options = _read_options(**inputs_opts)
    options = {"services": list(services) or None, "decorrelation": decorrelation, "confidence": confidence}
    with _staged(out_dir, "parametric") as stage, _progress() as bar:
        bar.add_task("parametric availability, integrity and continuity", total=None)
        if len(inputs) == 1 and is_dataset(inputs[0]):
            from overbound.campaign import partitions_in
            from overbound.campaign_parametric import campaign_parametric

            analysis = campaign_parametric(partitions_in(inputs[0]), **options)
            run = write_parametric_run(analysis, stage.path)
        else:
            table = _with_truth(*load_epochs(list(inputs), columns=("alert",), **read_options))
            run = run_parametric(table, stage.path, **options)
    for line in _parametric_lines(run.analysis):
        console.print(line, highlight=False, soft_wrap=True)
    click.echo(f"parametric: {stage.final(run.json_path)}")
    click.echo(f"report: {stage.final(run.report)}")


@main.command()
@click.option(
    "-o",
    "--output",
    "out_dir",
    default=Path("overbound-demo"),
    show_default=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Output directory of the demo's reports.",
)
@click.option(
    "--days",
    default=7.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Length of the simulated campaign.",
)
@click.option("--seed", default=2, show_default=True, type=int, help="Seed of the simulated campaign.")
@_draws_figures
def demo(out_dir, days, seed) -> None:
    """Analyse the embedded real WAAS day (USLO, 2006-12-27) and a simulated campaign."""
    with _staged(out_dir, "demo") as stage:
        real, simulated, index = _demo(stage.path, days, seed)
    click.echo(f"report: {stage.final(real[1])}")
    click.echo(f"report: {stage.final(simulated[1])}")
    click.echo(f"index:  {stage.final(index)}")


def _demo(out_dir: Path, days: float, seed: int):
    from overbound.io.geodesy import Reference
    from overbound.simulate import SimulationConfig, write_simulation
    from overbound.simulate import simulate as run

    with as_file(files("overbound.data") / DEMO_POS) as pos:
        real = _run_analysis(
            [pos],
            out_dir / "uslo",
            reference=Reference.parse(USLO_REFERENCE),
            title="USLO 2006-12-27, WAAS (RTKLIB-MOPS output)",
        )
    with tempfile.TemporaryDirectory() as tmp:
        with _progress() as bar:
            bar.add_task(f"simulating {days:g} days at 1 Hz", total=None)
            sim = run(SimulationConfig(days=days, seed=seed))
            path = Path(tmp) / "simulated.parquet"
            write_simulation(sim, path)
        simulated = _run_analysis(
            [path], out_dir / "simulated", title=f"Simulated {days:g}-day 1 Hz campaign"
        )
    index = _write_index(
        out_dir,
        [("USLO real WAAS day", real[1], real[2]), (f"Simulated {days:g} days", simulated[1], simulated[2])],
    )
    return real, simulated, index


def _write_index(out_dir: Path, reports: list) -> Path:
    """``index.html``: each report's verdict matrix, styled like the reports, linking to its evidence."""
    from overbound.report.page import PAGE_CSS, escape
    from overbound.report.verdicts import VERDICT_CSS, matrix_html

    parts = []
    for name, path, assessment in reports:
        href = escape(path.relative_to(out_dir).as_posix())
        parts.append(
            f'<section id="{escape(path.parent.name)}"><h2><a href="{href}">{escape(name)}</a></h2>'
            f"{matrix_html(assessment.services, link=href)}"
            f'<p><a href="{href}">Open the report</a> '
            "(verdict evidence, KPIs, the three methods, figures).</p>"
            "</section>"
        )
    path = out_dir / "index.html"
    path.write_text(
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>overbound demo</title>\n<style>{PAGE_CSS}{VERDICT_CSS}</style>\n</head>\n<body>\n<main>\n"
        '<header><p class="kicker">GNSS integrity verification</p><h1>overbound demo</h1>'
        '<p class="sub">The verdict of every service level for a real WAAS day and a simulated campaign; '
        "each cell links to the evidence it rests on.</p></header>\n"
        + "\n".join(parts)
        + "\n</main>\n</body>\n</html>\n",
        encoding="utf-8",
    )
    return path


class _ManyOption(click.Option):
    """A repeatable option that also takes several values after one flag: ``--obs a.19o b.19o``.

    Values are taken up to the next token that starts with ``-``.
    """

    def add_to_parser(self, parser, ctx: click.Context) -> None:
        super().add_to_parser(parser, ctx)
        for name in self.opts:
            opt = parser._long_opt.get(name) or parser._short_opt.get(name)
            if opt is None:  # pragma: no cover - click always registers the option's names
                continue
            take = opt.process

            def process(value, state, take=take) -> None:
                take(value, state)
                while state.rargs and not state.rargs[0].startswith("-"):
                    take(state.rargs.pop(0), state)

            opt.process = process


def _sbas_reference(lla: str | None, ecef: str | None):
    """--reference LAT,LON,H | mean, or --reference-ecef X,Y,Z; None for the RINEX header position."""
    if lla is not None and lla.strip().lower() == "mean":
        if ecef:
            raise click.UsageError("give --reference or --reference-ecef, not both")
        return "mean"
    return _reference(lla, ecef)


_FILES = click.Path(dir_okay=False, path_type=Path)


def _many_files(flag: str, dest: str, help_text: str, *, required: bool = False):
    """An option taking one or several files after one flag (``--nav a.19n b.19n``)."""
    return click.option(flag, dest, cls=_ManyOption, multiple=True, required=required, type=_FILES,
                        metavar="FILE...", help=help_text)  # fmt: skip


def _interval_option(default: float):
    return click.option("--interval", default=default, show_default=True, type=click.FloatRange(min=0.05),
                        help="Seconds between epochs.")  # fmt: skip


_mask_option = click.option(
    "--mask",
    "mask_deg",
    default=5.0,
    show_default=True,
    type=click.FloatRange(0, 90),
    help="Elevation mask (deg).",
)


@main.command()
@_many_files(
    "--obs", "obs", "Observations: RINEX 2/3 (plain, gzip, Hatanaka) or a u-blox UBX raw log (RXM-RAW/RAWX)."
)
@click.option(
    "--campaign",
    "campaign_file",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    help="A network campaign description (TOML: stations, file patterns with date tokens, days; see "
    "overbound.sbas_network), run station-day by station-day into --dataset instead of --obs/-o.",
)
@click.option(
    "--dataset",
    "dataset",
    type=click.Path(file_okay=False, path_type=Path),
    help="With --campaign: the campaign dataset each station-day is written into (created if needed).",
)
@click.option(
    "--workers",
    type=click.IntRange(min=0),
    metavar="N",
    help="With --campaign: N local worker processes (0: this process; default: one per core).",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    envvar="DASK_SCHEDULER_ADDRESS",
    help="With --campaign: run on the Dask cluster at ADDRESS (default $DASK_SCHEDULER_ADDRESS); the "
    "files and the dataset must be at the same absolute paths on its workers.",
)
@_many_files(
    "--nav", "nav", "GPS broadcast ephemerides (RINEX 2/3 navigation; default: those of a UBX log in --obs)."
)
@_many_files(
    "--sbas",
    "sbas_files",
    "SBAS messages: EMS files, RINEX-B (2.10/2.11 GEO SBAS broadcast) files or RTKLIB .sbs message "
    "logs (convbin -s: the route for Hemisphere, NovAtel and other raw logs via RTKLIB convbin), plain "
    "or gzip, recognised by content (default: the SBAS frames of a UBX log in --obs).",
)
@click.option(
    "--reference",
    "reference",
    metavar="LAT,LON,H|mean",
    help="True antenna position (deg, deg, ellipsoidal m), or 'mean': the mean of the SBAS "
    "solutions (default: the RINEX header position).",
)
@click.option("--reference-ecef", "reference_ecef", metavar="X,Y,Z", help="True antenna position, ECEF (m).")
@click.option(
    "--mode",
    type=click.Choice(["PA", "NPA"]),
    default="PA",
    show_default=True,
    help="Protection-level factors and message time-outs.",
)
@_mask_option
@click.option(
    "--geo",
    type=click.IntRange(120, 158),
    default=None,
    help="GEO PRN whose messages are used (default: the one received at each epoch).",
)
@click.option(
    "--station",
    "stations",
    cls=_ManyOption,
    multiple=True,
    metavar="NAME...",
    help="Station name: one for all --obs files (one receiver), or one per --obs file in their order. "
    "Default: files are told apart by RINEX marker name and header position (within 100 m), each "
    "station named by its marker or first file; u-blox logs, which carry neither, are one station.",
)
@click.option(
    "--all-subsets",
    "all_subsets",
    is_flag=True,
    help="Also write the Stanford-ESA all-subsets histogram (every subset of 4 or more used satellites "
    "per epoch): NAME.subsets.json and NAME.subsets.png.",
)
@click.option(
    "--service",
    "services",
    multiple=True,
    metavar="NAME|NAME:HAL:VAL",
    help="Service level of the --all-subsets counts (repeatable); default: LPV with --mode PA, NPA with "
    "--mode NPA.",
)
@_many_files(
    "--sp3",
    "sp3",
    "SP3 precise orbits and clocks over the observations: also write the range-domain errors "
    "normalised by their sigmas (GIMAT 3.4), NAME.range.parquet.",
)
@click.option(
    "-o",
    "--output",
    "out",
    type=_FILES,
    help="Epoch table (.parquet or .csv); the per-satellite table goes next to it (NAME.sats.parquet).",
)
def sbas(
    obs,
    campaign_file,
    dataset,
    workers,
    scheduler,
    nav,
    sbas_files,
    reference,
    reference_ecef,
    mode,
    mask_deg,
    geo,
    stations,
    all_subsets,
    services,
    sp3,
    out,
) -> None:
    """DO-229 SBAS engine: errors and protection levels from raw observations and SBAS messages.

    Observation files of several receivers are processed station by station, never merged, into
    one epoch table with a row per station and epoch (e.g. --obs TLSE0140.19o BRUX0140.19o).
    """
    given = _given_options(click.get_current_context())
    if campaign_file is not None:
        if obs or nav or sbas_files or out:
            raise click.UsageError(
                "--campaign names its own files: give --dataset, not --obs/--nav/--sbas/-o"
            )
        if dataset is None:
            raise click.UsageError("--campaign needs --dataset DIR")
        if given & _NOT_WITH_CAMPAIGN:
            raise click.UsageError(
                f"{', '.join(sorted(given & _NOT_WITH_CAMPAIGN))} with --campaign: its description sets "
                "the mode, mask, GEO and each station's reference; --all-subsets, --sp3 and --service "
                "take one station"
            )
        return _sbas_network(campaign_file, dataset, *_cluster_choice(workers, scheduler))
    if given & _CAMPAIGN_ONLY:
        raise click.UsageError(f"{', '.join(sorted(given & _CAMPAIGN_ONLY))}: with --campaign only")
    if not obs or out is None:
        raise click.UsageError("give --obs FILE... and -o FILE (or --campaign FILE --dataset DIR)")
    from overbound._allocator import keep_freed_memory
    from overbound.sbas.engine import SbasOptions
    from overbound.sbas.run import process_stations, write_runs
    from overbound.services import resolve_services

    if all_subsets or sp3:  # imported only when asked for: the Stanford counts pull in scipy (0.3-1 s)
        from overbound.report.sbas_products import range_product, subsets_product, write_range, write_subsets
    if services and not all_subsets:
        raise click.UsageError("--service sets the --all-subsets counts: give --all-subsets too")
    levels = resolve_services(list(services)) if services else None  # a bad name fails before the engine
    keep_freed_memory()  # the engine's column arrays: reuse freed memory instead of faulting in fresh pages
    ref = _sbas_reference(reference, reference_ecef)
    options = SbasOptions(mode=mode, mask_deg=mask_deg, geo=geo)
    with staged_files(out) as staged, _progress() as bar:
        task = bar.add_task("reading", total=None)

        def step(what: str) -> None:
            bar.update(task, description=what)

        runs = process_stations(list(obs), list(nav), list(sbas_files), reference=ref,
                                stations=list(stations) or None, options=options, progress=step)  # fmt: skip
        if len(runs) > 1 and (all_subsets or sp3):
            raise click.UsageError(
                f"--all-subsets and --sp3 take one station; the --obs files hold {len(runs)} "
                f"({', '.join(r.station for r in runs)}): run them one station at a time"
            )
        run = runs[0]
        # products before any writing: a bad SP3 file leaves no half-written output
        subsets = subsets_product(run, levels, progress=step) if all_subsets else None
        ranges = range_product(run, list(sp3), progress=step) if sp3 else None
        step(f"writing {out}")
        epochs_path, sats_path = write_runs(runs, staged)
        subsets_paths = write_subsets(subsets, run, staged) if subsets else None
        range_path = write_range(ranges, run, staged) if ranges else None
    # the paths where the files are now (renamed out of the staging directory)
    epochs_path, sats_path = out.parent / epochs_path.name, out.parent / sats_path.name
    subsets_paths = tuple(out.parent / p.name for p in subsets_paths) if subsets_paths else None
    range_path = out.parent / range_path.name if range_path else None
    for r in runs:
        console.print(_sbas_line(r, epochs_path, several=len(runs) > 1), highlight=False, soft_wrap=True)
    if subsets_paths:
        console.print(_subsets_line(subsets, subsets_paths[0]), highlight=False, soft_wrap=True)
    if range_path:
        console.print(_range_line(ranges, range_path), highlight=False, soft_wrap=True)
    click.echo(f"epochs: {epochs_path}")
    click.echo(f"satellites: {sats_path}")
    if subsets_paths:
        click.echo(f"subsets: {subsets_paths[0]}")
        click.echo(f"subsets figure: {subsets_paths[1]}")
    if range_path:
        click.echo(f"range: {range_path}")


#: ``overbound sbas`` options that a campaign description replaces, and those of a campaign only.
_NOT_WITH_CAMPAIGN = frozenset(
    {"--mode", "--mask", "--geo", "--reference", "--reference-ecef", "--station", "--all-subsets", "--sp3",
     "--service"}
)  # fmt: skip
_CAMPAIGN_ONLY = frozenset({"--dataset", "--workers", "--scheduler"})


def _given_options(ctx: click.Context) -> set[str]:
    """The long names of the options given on the command line (not defaults or the environment)."""
    from click.core import ParameterSource

    return {
        max(p.opts, key=len)
        for p in ctx.command.params
        if isinstance(p, click.Option) and ctx.get_parameter_source(p.name) == ParameterSource.COMMANDLINE
    }


def _sbas_network(campaign_file: Path, dataset: Path, workers: int | None, scheduler: str | None) -> None:
    """``overbound sbas --campaign``: every station-day into the dataset, a line per station."""
    from overbound.sbas_network import read_campaign, run_network

    campaign = read_campaign(campaign_file)
    with _campaign_client(dataset, workers, scheduler, lambda: False) as client, _progress() as bar:
        task = bar.add_task("reading", total=None)
        outcomes = run_network(
            campaign, dataset, client=client, progress=lambda d: bar.update(task, description=d)
        )
    for s in campaign.stations:
        mine = [o for o in outcomes if o.station == s.id]
        written = [o for o in mine if o.status == "written"]
        line = (
            f"{dataset} station {s.id}: {len(written)} of {len(mine)} days written, "
            f"{sum(o.epochs for o in written)} epochs, "
            f"{sum(o.solutions for o in written)} with a {campaign.options.mode} solution"
        )
        others = [f"{o.date} {o.status}: {o.reason}" for o in mine if o.status != "written"]
        console.print(line + ("; " + "; ".join(others) if others else ""), highlight=False, soft_wrap=True)
    click.echo(f"dataset: {dataset}")


def _sbas_line(run, path: Path, several: bool = False) -> str:
    """One line: epochs and solutions, PL medians, error percentiles, rejections and missing data
    (``several``: of one station among several in the file)."""
    import numpy as np

    e = run.epochs
    sol = e.filter(e["vpl"].is_finite())
    c = run.counts
    msgs = c["messages"]

    def pct(x, q) -> str:
        return _fmt(float(np.percentile(np.abs(x), q))) if len(x) else "n/a"

    rejected = ", ".join(f"{k} {v}" for k, v in c["rejected"].items()) or "none"
    miss = c["missing_ephemeris_rows"]
    prns = c["missing_ephemeris_prns"]
    geos = ", ".join(str(g) for g in sorted(set(e["geo"].to_list())))
    return (
        f"{path}{' station ' + run.station if several else ''}: "
        f"{e.height} epochs, {sol.height} with a {run.options.mode} solution (GEO {geos}); "
        f"HPL/VPL median {pct(sol['hpl'], 50)}/{pct(sol['vpl'], 50)} m; "
        f"HPE95 {pct(sol['hpe'], 95)} m, |VPE|95 {pct(sol['vpe'], 95)} m "
        f"(reference: {run.reference_source}); messages {msgs['messages']}, bad CRC {c['bad_crc']}; "
        f"rejected lines/records: {rejected}; observations without ephemeris: {miss}"
        + (f" (PRN {', '.join(map(str, prns))})" if prns else "")
        + (f"; duplicate observation records dropped: {c['duplicate_observation_rows']}"
           if c.get("duplicate_observation_rows") else "")
    )  # fmt: skip


def _subsets_line(product, path: Path) -> str:
    """One line: subsets and epochs, singular subsets, region counts per service, worst PE/PL."""
    first = product.results[product.services[0].name]
    parts = []
    for s in product.services:
        c = product.results[s.name].counts
        axes = [a for a in ("horizontal", "vertical") if s.alert_limit(a) is not None]
        parts.append(
            f"{s.name} " + "; ".join(
                f"{a[0].upper()}PL>=AL {c[a].unavailable + c[a].unavailable_mi}, MI {c[a].mi}, HMI {c[a].hmi}"
                for a in axes
            )
        )  # fmt: skip
    w = first.worst_ratio
    return (
        f"{path}: {first.n_subsets} subsets of {first.n_epochs} epochs "
        f"({first.n_singular} singular left out); "
        + ", ".join(parts)
        + f"; worst PE/PL H {_fmt(w['horizontal'])}, V {_fmt(w['vertical'])}"
    )


def _range_line(product, path: Path) -> str:
    """One line: ranges compared, normalised-error spread, ranges without SP3 data."""
    import numpy as np

    c = product.counts
    x = np.abs(product.table["normalised"].to_numpy())
    prns = c["prns_without_sp3"]
    return (
        f"{path}: {c['rows']} ranges of {c['satellites']} satellites over {c['epochs']} epochs against SP3 "
        f"({', '.join(Path(f).name for f in product.sp3_files)}); "
        f"|error/sigma| 95 % {_fmt(np.percentile(x, 95))}, "
        f"max {_fmt(x.max())}; used ranges without SP3 data: {c['rows_without_sp3']}"
        + (f" (PRN {', '.join(map(str, prns))})" if prns else "")
    )


@main.command("sbas-map")
@_many_files("--nav", "nav", "GPS broadcast ephemerides (RINEX navigation).", required=True)
@_many_files("--sbas", "sbas_files", "SBAS messages: EMS, RINEX-B or RTKLIB .sbs files.", required=True)
@click.option(
    "--area",
    nargs=4,
    type=float,
    default=(-30.0, 40.0, 25.0, 70.0),
    show_default=True,
    metavar="LON0 LON1 LAT0 LAT1",
    help="Grid extent, deg: nodes every --step from LON0 and LAT0, up to LON1 and LAT1.",
)
@click.option(
    "--step", default=1.0, show_default=True, type=click.FloatRange(min=0.01), help="Grid step, deg."
)
@_interval_option(60.0)
@click.option(
    "--height",
    "height_m",
    default=0.0,
    show_default=True,
    type=float,
    help="Receiver height above the ellipsoid, m.",
)
@_services_option
@click.option(
    "--mode",
    type=click.Choice(["PA", "NPA"]),
    default="PA",
    show_default=True,
    help="Precision approach (PA: HPL and VPL with K 6.0 and 5.33) or non-precision (NPA: HPL, K 6.18).",
)
@_mask_option
@click.option("--geo", type=int, default=None, help="PRN of the GEO whose messages are used.")
@click.option(
    "--start",
    "start",
    default=None,
    type=click.DateTime(["%Y-%m-%dT%H:%M:%S", "%Y-%m-%d"]),
    help="First epoch (GPS time; default: the start of the first message's GPS day).",
)
@click.option(
    "--end",
    "end",
    default=None,
    type=click.DateTime(["%Y-%m-%dT%H:%M:%S", "%Y-%m-%d"]),
    help="Epochs before this time (default: up to the last message + 1 s).",
)
@click.option("--hourly", is_flag=True, help="Also one row per grid point, service and hour.")
@click.option("--maritime", is_flag=True, help="Continuity over 15-minute windows instead of 15 s.")
@click.option(
    "--workers",
    type=click.IntRange(min=0),
    metavar="N",
    help="N local worker processes (0, the default: this process).",
)
@click.option("--scheduler", metavar="ADDRESS", help="Run on the Dask cluster at ADDRESS.")
@_output_dir("Directory of map.parquet, map.json and map.html, written whole or not at all.")
def sbas_map(
    nav,
    sbas_files,
    area,
    step,
    interval,
    height_m,
    services,
    mode,
    mask_deg,
    geo,
    start,
    end,
    hourly,
    maritime,
    workers,
    scheduler,
    out_dir,
) -> None:
    """Service-volume maps (availability, continuity, ionosphere, PL percentiles) from SBAS messages."""
    from overbound.report.sbas_map import write_map
    from overbound.sbas.engine import SbasOptions
    from overbound.sbas.maps import MapGrid
    from overbound.sbas_map import MapOptions, compute_map
    from overbound.services import resolve_services

    lon0, lon1, lat0, lat1 = area
    if not (lon0 <= lon1 and -90 <= lat0 <= lat1 <= 90):
        raise click.BadParameter("expected LON0 <= LON1 and -90 <= LAT0 <= LAT1 <= 90", param_hint="--area")

    def us(d):
        return None if d is None else int((d - datetime.datetime(1970, 1, 1)).total_seconds()) * 1_000_000

    options = MapOptions(
        grid=MapGrid(lon0, lon1, lat0, lat1, step, height_m), interval_s=interval, start_us=us(start),
        end_us=us(end), services=resolve_services(list(services)) if services else (),
        engine=SbasOptions(mode=mode, mask_deg=mask_deg, geo=geo), hourly=hourly, maritime=maritime,
    )  # fmt: skip
    inputs = [("nav", p) for p in nav] + [("sbas", p) for p in sbas_files]
    workers, scheduler = _cluster_choice(workers, scheduler)
    with _staged(out_dir, "sbas-map") as stage:
        with _campaign_client(out_dir, workers, scheduler, lambda: True) as client, _progress() as bar:
            task = bar.add_task("reading", total=None)
            smap = compute_map(list(nav), list(sbas_files), options, client=client,
                               progress=lambda d: bar.update(task, description=d))  # fmt: skip
        paths = write_map(stage.path, smap, inputs)
    for s in options.chosen_services():
        click.echo(
            f"{s.name}: {100 * smap.share_above(s.name):.1f} % of the grid points at 99 % availability "
            "or more"
        )
    for p in paths:
        click.echo(f"{stage.final(p)}")


@main.command("synth-obs")
@_many_files(
    "--sp3",
    "sp3",
    "Precise orbits and clocks (SP3; the adjoining days' files too to cover midnight).",
    required=True,
)
@_many_files(
    "--nav",
    "nav",
    "GPS broadcast ephemerides (health and TGD of the records a receiver would use).",
    required=True,
)
@_many_files("--ionex", "ionex", "Global ionosphere maps (IONEX).", required=True)
@click.option(
    "--dcb",
    "p1c1",
    required=True,
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    help="CODE P1-C1 differential code biases (P1C1yymm.DCB).",
)
@click.option("--day", required=True, type=click.DateTime(["%Y-%m-%d"]), help="GPS day, YYYY-MM-DD.")
@click.option(
    "--point",
    "points",
    multiple=True,
    metavar="NAME,LAT,LON,H",
    help="A static receiver (repeatable); default: ten points across Europe "
    "(overbound.sbas.synthetic_obs.EUROPE).",
)
@_interval_option(30.0)
@click.option(
    "--start",
    "start_s",
    default=0.0,
    show_default=True,
    type=click.FloatRange(0, 86_400),
    help="First epoch, seconds of the day.",
)
@click.option(
    "--end",
    "end_s",
    default=86_400.0,
    show_default=True,
    type=click.FloatRange(0, 86_400),
    help="Epochs before this second of the day.",
)
@_mask_option
@_output_dir("Directory of the RINEX files (SSSSDDD0.YYo.gz), written whole or not at all.")
def synth_obs(sp3, nav, ionex, p1c1, day, points, interval, start_s, end_s, mask_deg, out_dir) -> None:
    """Noise-free GPS L1 observations of static points from precise products (RINEX 2.11)."""
    from overbound.sbas.synthetic_obs import EUROPE, SyntheticPoint, rinex_name, write_network

    try:
        chosen = [SyntheticPoint.parse(p) for p in points] or list(EUROPE)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--point") from None
    names = [rinex_name(p, day.date()) for p in chosen]  # the file names: 4 characters, upper case
    if len(set(names)) != len(names):
        raise click.BadParameter(f"points would share a file: {', '.join(names)}", param_hint="--point")
    if start_s >= end_s:
        raise click.BadParameter("--start must be before --end", param_hint="--start")
    with _staged(out_dir, "synth-obs") as stage:
        written, reports = write_network(
            chosen, day.date(), stage.path, sp3=list(sp3), nav=list(nav), ionex=list(ionex), p1c1=p1c1,
            interval_s=interval, start_s=start_s, end_s=end_s, mask_deg=mask_deg,
        )  # fmt: skip
    for r in reports:
        click.echo(
            f"{r.source} ({r.format}): {r.rows_kept} of {r.rows_read} rows kept, rejected "
            f"{dict(sorted(r.rejected.items()))}, invalidated {dict(sorted(r.invalidated.items()))}"
        )
    for w in written:
        p = w.point
        click.echo(f"{stage.final(w.path)}: {p.name} {p.lat_deg:.4f} {p.lon_deg:.4f} {p.height_m:.1f} m, "
                   f"{w.n_epochs} epochs, {w.n_records} satellite records")  # fmt: skip


@main.command()
def schema() -> None:
    """Print the epoch table's columns (Markdown)."""
    from overbound.io.schema import schema_markdown

    click.echo(schema_markdown())


if __name__ == "__main__":  # pragma: no cover
    main()


#: One example per command, shown at the end of its --help (the files named exist in the repository).
_EXAMPLES = {
    "analyze": "overbound analyze src/overbound/data/uslo-2006-361-waas.pos.gz --reference "
    "35.311803,-120.661092,134.6419 -o out/\n  overbound analyze tests/data/g1000/*.csv.gz "
    "tests/data/g1000/ProximityTestFlights.zip -o flights/\n  overbound analyze "
    "tests/data/truth/rover.pos.gz --truth tests/data/truth/rover-truth.pos.gz -o rover/",
    "confidence": "overbound confidence src/overbound/data/uslo-2006-361-waas.pos.gz --reference "
    "35.311803,-120.661092,134.6419 -o cl/",
    "convert": "overbound convert src/overbound/data/uslo-2006-361-waas.pos.gz --reference mean "
    "-o uslo.parquet",
    "demo": "overbound demo -o overbound-demo/",
    "evt": "overbound evt sim.parquet -o evt/   (sim.parquet from: overbound simulate -o sim.parquet)",
    "ingest": "overbound ingest net/ day1.pos day2.pos --reference 43.56,1.48,200",
    "parametric": "overbound parametric sim.parquet -o par/",
    "sbas": "overbound sbas --obs tests/data/sbas/engine/SYNT0140_h02-04.19o.gz --nav "
    "tests/data/sbas/engine/brdc0140.19n.gz --sbas tests/data/sbas/engine/h03.ems.gz -o synt.parquet",
    "sbas-map": "overbound sbas-map --nav tests/data/sbas/engine/brdc0140.19n.gz --sbas "
    "tests/data/sbas/network/egnos123_2019014.ems.gz --step 2 -o map/",
    "schema": "overbound schema",
    "simulate": "overbound simulate -o sim.parquet --days 7 --seed 1 --stations 3",
    "synth-obs": "overbound synth-obs --sp3 tests/data/sbas/network/igs20361.sp3.gz --nav "
    "tests/data/sbas/engine/brdc0140.19n.gz --ionex tests/data/sbas/network/igsg0140.19i.gz --dcb "
    "tests/data/sbas/network/P1C11901.DCB --day 2019-01-14 --point TLSE,43.56,1.48,200 -o obs/",
}
for _name, _text in _EXAMPLES.items():
    main.commands[_name].epilog = "\b\nExample:\n  " + _text
