"""``reference="mean"`` (``--reference mean``): errors against the mean of the receiver's own positions.

The mean is checked against an independent computation (the positions parsed here, converted with
pymap3d, averaged in ECEF), the errors against a second read with that position given as a plain
reference, and the property that defines it: the errors of the epochs averaged average to zero.
"""

from __future__ import annotations

import gzip
import io
import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.geodesy import MEAN_POSITION, Reference, resolve, resolve_geodetic
from overbound.io.glab import read_glab
from overbound.io.rtklib import read_rtklib_pos
from overbound.io.schema import InputError
from overbound.io.table import read_csv
from overbound.io.ubx import read_ubx

USLO = Path(str(files("overbound") / "data" / "uslo-2006-361-waas.pos.gz"))
DATA = Path(__file__).resolve().parents[1] / "data"
MEAN_NOTE = "(the mean of the receiver's own positions, not truth)"


def _uslo_llh() -> np.ndarray:
    rows = [ln.split() for ln in gzip.decompress(USLO.read_bytes()).decode().splitlines() if ln[:1] != "%"]
    return np.array([[float(f[2]), float(f[3]), float(f[4])] for f in rows])


def _mean_reference(llh: np.ndarray) -> Reference:
    xyz = np.column_stack(pymap3d.geodetic2ecef(llh[:, 0], llh[:, 1], llh[:, 2]))
    return Reference(*(float(v) for v in pymap3d.ecef2geodetic(*xyz.mean(axis=0))))


def _assert_zero_mean(table) -> None:
    ok = np.isfinite(table["vpe"].to_numpy())
    assert ok.sum() > 0
    enu = np.column_stack([table[c].to_numpy()[ok] for c in ("east", "north", "vpe")])
    # ENU is a rotation of the ECEF differences: the mean error is the rotated (mean - mean) = 0
    np.testing.assert_allclose(enu.mean(axis=0), 0.0, atol=1e-6)
    assert np.abs(enu).max() > 0.01  # and the errors are not all zero


def test_resolve_is_the_ecef_mean_of_the_positions_used():
    llh = _uslo_llh()
    xyz = pymap3d.geodetic2ecef(llh[:, 0], llh[:, 1], llh[:, 2])
    use = np.arange(llh.shape[0]) % 3 == 0
    got = resolve(MEAN_POSITION, *xyz, use)
    want = _mean_reference(llh[use])
    assert (got.lat_deg, got.lon_deg, got.height_m) == pytest.approx(
        (want.lat_deg, want.lon_deg, want.height_m), abs=1e-9
    )
    assert resolve_geodetic(MEAN_POSITION, *llh.T) == pytest.approx(_mean_reference(llh), abs=1e-9)
    truth = Reference(35.3, -120.6, 100.0)
    assert resolve(truth, *xyz) is truth  # a given position is used as it is
    nan = np.full(3, np.nan)
    with pytest.raises(InputError, match=r"here\.pos: reference mean: no position to average"):
        resolve(MEAN_POSITION, nan, nan, nan, source="here.pos")


def test_rtklib_mean_reference_is_the_mean_solution_and_says_so():
    table, report = read_rtklib_pos(USLO, reference=MEAN_POSITION)
    want = _mean_reference(_uslo_llh())  # every epoch of this file has a solution (Q 2)
    note = next(n for n in report.notes if n.startswith("reference "))
    assert note.endswith(MEAN_NOTE)
    lat, lon, h = (float(v) for v in note.split()[1].split(","))
    assert (lat, lon, h) == pytest.approx((want.lat_deg, want.lon_deg, want.height_m), abs=1e-4)
    _assert_zero_mean(table)
    again, _ = read_rtklib_pos(USLO, reference=want)
    for c in ("east", "north", "hpe", "vpe"):
        np.testing.assert_allclose(table[c].to_numpy(), again[c].to_numpy(), rtol=0, atol=1e-6)


def test_csv_positions_against_the_mean():
    llh = _uslo_llh()[:50]
    text = "time,lat,lon,height,hpl,vpl\n" + "".join(
        f"2006-12-27T00:{i // 60:02d}:{i % 60:02d},{a!r},{b!r},{c!r},20.0,30.0\n"
        for i, (a, b, c) in enumerate(llh.tolist())
    )
    table, report = read_csv(io.StringIO(text), station="USLO", reference=MEAN_POSITION)
    assert any(n.endswith(MEAN_NOTE) for n in report.notes)
    _assert_zero_mean(table)
    again, _ = read_csv(io.StringIO(text), station="USLO", reference=_mean_reference(llh))
    np.testing.assert_allclose(table["vpe"].to_numpy(), again["vpe"].to_numpy(), rtol=0, atol=1e-6)


def test_ubx_mean_over_the_usable_epochs():
    table, report = read_ubx(DATA / "ubx" / "pvt_pl_timegps.ubx", reference=MEAN_POSITION)
    assert any(MEAN_NOTE in n for n in report.notes)
    _assert_zero_mean(table)


def test_glab_mean_needs_output_lines():
    edge = DATA / "glab" / "edge" / "apriori_calculated.glab"
    table, report = read_glab(edge, reference=MEAN_POSITION)
    assert any(MEAN_NOTE in n for n in report.notes)
    _assert_zero_mean(table)
    text = "".join(ln for ln in edge.open() if not ln.startswith("OUTPUT"))
    with pytest.raises(InputError, match="reference mean needs the OUTPUT lines"):
        read_glab(io.StringIO(text), reference=MEAN_POSITION)


def _analyze(tmp_path: Path, name: str, *options: str) -> tuple[dict, str]:
    out = tmp_path / name
    args = ["analyze", str(USLO), "-o", str(out), "--no-evt", "--no-parametric", "--no-confidence", *options]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text()), (out / "report.html").read_text()


def test_analyze_reference_mean_warns_first(tmp_path: Path):
    summary, html = _analyze(tmp_path, "mean", "--reference", "mean")
    assert len(summary["warnings"]) == 1 and "mean of the receiver's own positions" in summary["warnings"][0]
    header = html[html.index("<header>") : html.index("</header>")]
    assert 'class="warning"' in header and "not a surveyed position" in header
    truth, html_truth = _analyze(tmp_path, "truth", "--reference", "35.311803,-120.661092,134.6419")
    assert "warnings" not in truth and 'class="warning"' not in html_truth
    # the same epochs, the errors smaller about their own mean than against truth (a bias removed)
    assert summary["epochs"] == truth["epochs"]
    assert summary["accuracy"]["vpe95"] < truth["accuracy"]["vpe95"]


@pytest.mark.parametrize("height, warned", [(134.6419 + 100.0, True), (134.6419 + 20.0, False)])
def test_analyze_warns_on_an_implausible_error_scale(tmp_path: Path, height: float, warned: bool):
    summary, html = _analyze(tmp_path, "h", "--reference", f"35.311803,-120.661092,{height}")
    warnings = summary.get("warnings", [])
    assert any("implausible" in w for w in warnings) is warned
    assert ("Check the reference position" in html) is warned
