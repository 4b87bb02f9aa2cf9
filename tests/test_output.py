"""Output directories written whole or not at all (overbound.output), and the commands that use them."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from importlib.resources import files
from pathlib import Path

import pytest
from click.testing import CliRunner

from overbound.cli import DEMO_POS, USLO_REFERENCE, main
from overbound.output import MANIFEST, OutputError, staged_directory, staged_files

POS = Path(str(files("overbound.data") / DEMO_POS))


def _tree(root: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``root``."""
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _leftovers(target: Path) -> list[str]:
    return sorted(p.name for p in target.parent.glob(f".{target.name}.*"))


def test_new_directory_appears_whole_with_its_manifest(tmp_path: Path) -> None:
    target = tmp_path / "deep" / "out"
    with staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("{}")
        (stage.path / "sub").mkdir()
        (stage.path / "sub" / "report.html").write_text("<p>")
        assert not target.exists(), "nothing is visible before the commit"
    assert stage.final(stage.path / "sub" / "report.html") == target / "sub" / "report.html"
    manifest = json.loads((target / MANIFEST).read_text())
    assert manifest["files"] == {"analyze": ["sub/report.html", "summary.json"]}
    assert _leftovers(target) == []


def test_stale_files_of_the_same_command_go_and_others_stay(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("old")
        (stage.path / "evt-horizontal.json").write_text("old")
    with staged_directory(target, command="evt") as stage:
        (stage.path / "evt-vertical.json").write_text("evt")
    (target / "notes.txt").write_text("mine")
    with staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    assert stage.removed == ["evt-horizontal.json"]
    assert stage.kept == ["evt-vertical.json", "notes.txt"]
    assert {p.name for p in target.iterdir()} == {"summary.json", "evt-vertical.json", "notes.txt", MANIFEST}
    assert (target / "summary.json").read_text() == "new" and (target / "notes.txt").read_text() == "mine"
    manifest = json.loads((target / MANIFEST).read_text())["files"]
    assert manifest == {"analyze": ["summary.json"], "evt": ["evt-vertical.json"]}


def test_a_failing_run_leaves_the_old_set_untouched(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("old")
    before = _tree(target)
    with pytest.raises(RuntimeError), staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("half")
        raise RuntimeError("analysis failed")
    assert _tree(target) == before
    assert _leftovers(target) == []


def test_a_second_run_on_a_directory_in_use_stops(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with staged_directory(target, command="analyze"):
        with pytest.raises(OutputError, match="in use by another overbound run"):
            with staged_directory(target, command="analyze"):
                pass
        with pytest.raises(OutputError, match="in use"):
            with staged_files(tmp_path / "out"):
                pass


def test_leftovers_of_a_killed_run_are_removed(tmp_path: Path) -> None:
    target = tmp_path / "out"
    (tmp_path / ".out.staging-99999").mkdir()
    (tmp_path / ".out.staging-99999" / "summary.json").write_text("half")
    with staged_directory(target, command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    assert _leftovers(target) == []


def test_directories_merge_file_by_file(tmp_path: Path) -> None:
    """Review of issue 13: a user's file inside a directory that the run also writes survived
    nowhere (the whole directory was replaced)."""
    target = tmp_path / "out"
    (target / "uslo").mkdir(parents=True)
    (target / "uslo" / "notes.txt").write_text("mine")
    (target / "empty").mkdir()
    with staged_directory(target, command="demo") as stage:
        (stage.path / "uslo").mkdir()
        (stage.path / "uslo" / "summary.json").write_text("1")
        (stage.path / "uslo" / "old.json").write_text("1")
    with staged_directory(target, command="demo") as stage:
        (stage.path / "uslo").mkdir()
        (stage.path / "uslo" / "summary.json").write_text("2")
    assert (target / "uslo" / "notes.txt").read_text() == "mine" and (target / "empty").is_dir()
    assert (target / "uslo" / "summary.json").read_text() == "2"
    assert stage.removed == ["uslo/old.json"] and stage.kept == ["empty", "uslo/notes.txt"]


def test_a_symlinked_target_is_written_through(tmp_path: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real)
    with staged_directory(tmp_path / "link", command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    assert (tmp_path / "link").is_symlink() and (real / "summary.json").read_text() == "new"
    assert _leftovers(real) == [] and _leftovers(tmp_path / "link") == []


def test_leftover_names_are_matched_exactly(tmp_path: Path) -> None:
    """A user's ``.out.old-backup`` and another target's staging (``a*`` globbing) are not ours."""
    (tmp_path / ".out.old-backup").write_text("user")
    (tmp_path / ".aXb.staging-7").mkdir()
    with staged_directory(tmp_path / "out", command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    with staged_directory(tmp_path / "a*", command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    assert (tmp_path / ".out.old-backup").exists() and (tmp_path / ".aXb.staging-7").exists()


def test_a_swap_killed_between_its_renames_is_repaired(tmp_path: Path) -> None:
    """Without an atomic exchange the swap is two renames; a kill between them leaves the
    previous set aside and no target. The next run puts it back before anything else."""
    aside = tmp_path / ".out.old-4242"
    aside.mkdir()
    (aside / "notes.txt").write_text("mine")
    (tmp_path / ".out.staging-4242").mkdir()
    with staged_directory(tmp_path / "out", command="analyze") as stage:
        (stage.path / "summary.json").write_text("new")
    assert (tmp_path / "out" / "notes.txt").read_text() == "mine" and stage.kept == ["notes.txt"]
    assert _leftovers(tmp_path / "out") == []


def test_epochs_inside_the_output_are_one_of_its_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main,
        ["analyze", str(POS), "--reference", USLO_REFERENCE, "--no-evt", "--no-parametric", "--no-confidence",
         "-o", str(out), "--epochs", str(out / "tables" / "epochs.parquet")],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "kept in" not in res.output
    manifest = json.loads((out / MANIFEST).read_text())["files"]["analyze"]
    assert manifest == ["report.html", "summary.json", "tables/epochs.parquet"]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: (d / "file").write_text("x") and d / "file" / "out", "is a file"),
        (lambda d: (d / "out").write_text("x") and d / "out", "is a file"),
        (lambda d: d / ("x" * 300), "cannot"),
    ],
    ids=["parent-is-a-file", "target-is-a-file", "name-too-long"],
)
def test_unwritable_targets_fail_before_any_work(tmp_path: Path, make, message: str) -> None:
    target = make(tmp_path)
    with pytest.raises(OutputError, match=message) as err:
        with staged_directory(target, command="analyze"):
            pytest.fail("the body must not run")
    assert "\n" not in str(err.value) and str(tmp_path) in str(err.value)


def test_current_directory_is_refused(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(OutputError, match="current directory"):
        with staged_directory(".", command="analyze"):
            pass


def test_staged_files_move_the_set_into_place(tmp_path: Path) -> None:
    target = tmp_path / "run.parquet"
    target.write_text("old")
    with staged_files(target) as path:
        assert path.name == "run.parquet" and path.parent != tmp_path
        path.write_text("new")
        path.with_name("run.sats.parquet").write_text("sats")
        assert target.read_text() == "old"
    assert target.read_text() == "new" and (tmp_path / "run.sats.parquet").read_text() == "sats"
    assert _leftovers(target) == []


def test_analyze_checks_the_output_before_reading(tmp_path: Path, monkeypatch) -> None:
    import overbound.analysis

    def never(*args, **kwargs):
        raise AssertionError("the analysis ran before the output was checked")

    monkeypatch.setattr(overbound.analysis, "analyze", never)
    (tmp_path / "file").write_text("x")
    for out in (tmp_path / "file" / "out", tmp_path / ("y" * 300)):
        res = CliRunner().invoke(main, ["analyze", str(POS), "--reference", USLO_REFERENCE, "-o", str(out)])
        assert res.exit_code == 2, res.output
        assert res.output.startswith("error: ") and res.output.count("\n") == 1, res.output
    res = CliRunner().invoke(
        main,
        [
            "analyze",
            str(POS),
            "--reference",
            USLO_REFERENCE,
            "-o",
            str(tmp_path / "o"),
            "--epochs",
            str(tmp_path),
        ],
    )
    assert res.exit_code == 2 and "is a directory" in res.output, res.output


def _analyze(out: Path, *extra: str) -> subprocess.Popen:
    cmd = [
        sys.executable,
        "-m",
        "overbound",
        "analyze",
        str(POS),
        "--reference",
        USLO_REFERENCE,
        "-o",
        str(out),
    ]
    env = {**os.environ, "OVERBOUND_FIGURE_PROCESSES": "1"}
    return subprocess.Popen([*cmd, *extra], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.mark.slow
def test_killing_analyze_leaves_the_old_or_the_new_set(tmp_path: Path) -> None:
    """SIGKILL at spread moments of a run (including its last tenth), and one SIGTERM: the
    directory always holds exactly the previous run's files or exactly the new run's."""
    out = tmp_path / "out"
    # old set: counting only; new set: every method (more files, other bytes)
    assert _analyze(out, "--no-confidence", "--no-evt", "--no-parametric").wait() == 0
    old = _tree(out)
    saved = tmp_path / "saved-old"
    shutil.copytree(out, saved)
    start = time.monotonic()
    assert _analyze(out).wait() == 0
    duration = time.monotonic() - start
    new = _tree(out)
    assert set(new) > set(old) and new["summary.json"] != old["summary.json"]
    seen = set()
    for share, sig in [
        (0.3, signal.SIGKILL),
        (0.9, signal.SIGKILL),
        (1.0, signal.SIGKILL),
        (0.6, signal.SIGTERM),
    ]:
        shutil.rmtree(out)
        shutil.copytree(saved, out)
        proc = _analyze(out)
        time.sleep(share * duration)
        proc.send_signal(sig)
        proc.wait()
        state = _tree(out)
        assert state in (old, new), f"kill at {share:.0%}: a mixed set {sorted(state)}"
        seen.add("new" if state == new else "old")
        if sig == signal.SIGTERM:
            assert _leftovers(out) == [], "a terminated run cleans up its staging directory"
    assert "old" in seen


@pytest.mark.slow
def test_outputs_are_byte_identical_whatever_the_threads_and_folder(tmp_path: Path) -> None:
    """Issue 13: OPENBLAS_NUM_THREADS=1 vs 2 changed the last digits of parametric.json (BLAS
    splits a long dot product across its threads). Same input, other folder, other thread
    counts of BLAS, OpenMP and polars: every file of the output is the same bytes."""
    from overbound.simulate import SimulationConfig, simulate, write_simulation

    trees = []
    for threads, folder in (("1", "a"), ("2", "b")):
        work = tmp_path / folder
        work.mkdir()
        write_simulation(simulate(SimulationConfig(days=0.5, seed=3)), work / "campaign.parquet")
        env = {
            **os.environ,
            "OVERBOUND_FIGURE_PROCESSES": "1",
            **{k: threads for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")},
            "POLARS_MAX_THREADS": threads,
        }
        cmd = [sys.executable, "-m", "overbound", "analyze", "campaign.parquet", "--no-evt", "-o", "out"]
        subprocess.run(cmd, cwd=work, env=env, check=True, capture_output=True)
        trees.append(_tree(work / "out"))
    assert set(trees[0]) >= {"summary.json", "report.html", "parametric.json", "confidence-vertical.json"}
    assert trees[0] == trees[1], [k for k in trees[0] if trees[0][k] != trees[1].get(k)]


def test_a_second_analyze_into_a_directory_in_use_stops_at_once(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with staged_directory(out, command="analyze"):  # a run in progress holds the lock
        res = CliRunner().invoke(main, ["analyze", str(POS), "--reference", USLO_REFERENCE, "-o", str(out)])
    assert res.exit_code == 2
    assert res.output == f"error: {out}: in use by another overbound run (lock .out.lock); wait for it\n"


def test_the_two_rename_fallback_gives_the_same_result(tmp_path: Path, monkeypatch) -> None:
    """macOS, Windows and file systems without RENAME_EXCHANGE take the two-rename path."""
    import overbound.output

    monkeypatch.setattr(overbound.output, "_exchange", lambda a, b: False)
    target = tmp_path / "out"
    for text in ("old", "new"):
        with staged_directory(target, command="analyze") as stage:
            (stage.path / "summary.json").write_text(text)
    assert (target / "summary.json").read_text() == "new" and _leftovers(target) == []
