"""Every command's --help: each option explained, one example at the end whose repository files exist."""

from __future__ import annotations

import glob
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from overbound.cli import _EXAMPLES, main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(main.commands))
def test_every_option_has_help_and_the_command_an_example(name):
    cmd = main.commands[name]
    assert [p.opts[0] for p in cmd.params if isinstance(p, click.Option) and not p.help] == []
    assert name in _EXAMPLES
    result = CliRunner().invoke(main, [name, "--help"])
    out = result.output
    assert result.exit_code == 0 and "error:" not in out  # click's Exit is a RuntimeError since 8.2
    assert "Example:" in out and f"overbound {name}" in out.split("Example:")[1]


@pytest.mark.parametrize("name", sorted(_EXAMPLES))
def test_example_files_exist(name):
    words = [w for w in _EXAMPLES[name].split() if w.startswith(("src/", "tests/"))]
    for w in words:
        assert glob.glob(str(ROOT / w)), f"{name}: {w} names no file"


def test_help_and_version_exit_zero_from_the_console_script():
    """In a fresh interpreter (``python -m overbound``), as a user runs it: click's Exit is no error."""
    import subprocess
    import sys

    for args in (["--help"], ["--version"], ["analyze", "--help"]):
        run = subprocess.run([sys.executable, "-m", "overbound", *args], capture_output=True, text=True)
        assert run.returncode == 0 and "error:" not in run.stdout + run.stderr, (args, run.stdout[-300:])
