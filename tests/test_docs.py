"""The documentation is true: the site builds with --strict, and every command in README.md and docs/ runs.

Each page's ``bash`` and ``python`` blocks run in order, as written, in a fresh directory that holds
the repository's ``src`` and ``tests`` (the commands are written to run from the repository's root);
a ``# prints: TEXT`` comment in a block requires TEXT in its output. ``text`` blocks are synopses
(``[--option VALUE]``, placeholders): each ``overbound`` line there must name a command and options
that exist. The set-up block (``python3 -m venv``) is CI's own command, not rerun here.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest

from overbound.cli import main

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.S | re.M)


def _blocks(page: Path, lang: str) -> list[str]:
    text = page.read_text(encoding="utf-8")
    return [body for kind, body in FENCE.findall(text) if kind == lang and "python3 -m venv" not in body]


def _environment(tmp_path: Path) -> dict[str, str]:
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONWARNINGS="ignore")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"  # this interpreter's overbound
    env["HOME"] = str(tmp_path)
    return env


def _workdir(tmp_path: Path) -> Path:
    work = tmp_path / "repo"
    work.mkdir()
    for name in ("src", "tests"):
        (work / name).symlink_to(ROOT / name)
    return work


def _run(cmd: list[str], cwd: Path, env: dict[str, str], what: str) -> str:
    run = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    out = run.stdout + run.stderr
    assert run.returncode == 0, f"{what} failed ({run.returncode}):\n{out[-3000:]}"
    return out


def _commands(page: Path) -> list[tuple[str, str]]:
    return [("bash", b) for b in _blocks(page, "bash")] + [("python", b) for b in _blocks(page, "python")]


@pytest.mark.parametrize(
    "page", [p for p in PAGES if _commands(p)], ids=lambda p: str(p.relative_to(ROOT))
)  # fmt: skip
def test_every_command_of_the_page_runs(page, tmp_path):
    work, env = _workdir(tmp_path), _environment(tmp_path)
    for kind, body in _commands(page):
        what = f"{page.name}: {body.strip().splitlines()[0]}"
        if kind == "bash":
            out = _run(["bash", "-euo", "pipefail", "-c", body], work, env, what)
        else:
            out = _run([sys.executable, "-c", body], work, env, what)
        for expected in re.findall(r"^# prints: (.+)$", body, re.M):
            assert expected.strip() in out, f"{what}: {expected.strip()!r} not in the output:\n{out[-2000:]}"


def _synopses() -> list[tuple[str, str]]:
    found = []
    for page in PAGES:
        for body in _blocks(page, "text"):
            joined = re.sub(r"\\\n\s*", " ", body)
            found += [
                (page.name, ln.strip()) for ln in joined.splitlines() if ln.strip().startswith("overbound ")
            ]
    return found


@pytest.mark.parametrize("page,line", _synopses())
def test_synopsis_names_real_options(page, line):
    words = line.split()
    command = main.commands.get(words[1])
    assert isinstance(command, click.Command), f"{page}: no command {words[1]!r}"
    known = {o for p in command.params for o in (*getattr(p, "opts", ()), *getattr(p, "secondary_opts", ()))}
    named = {w.strip("[]|,") for w in words[2:] if w.strip("[").startswith("--")}
    assert named <= known, f"{page}: {line!r} names {sorted(named - known)}, not options of {words[1]}"


def test_the_site_builds_strict(tmp_path):
    """``mkdocs build --strict``: a broken link, anchor or API reference fails the build."""
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")]
    run = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    assert "confidence_analysis" in api and "Parameters" in api  # mkdocstrings rendered the docstrings


def test_readme_and_home_page_give_the_same_set_up():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    home = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    first = FENCE.search(readme).group(2)
    assert "python3 -m venv" in first and first in home
