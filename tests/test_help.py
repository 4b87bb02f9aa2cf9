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
    out = CliRunner().invoke(main, [name, "--help"]).output
    assert "Example:" in out and f"overbound {name}" in out.split("Example:")[1]


@pytest.mark.parametrize("name", sorted(_EXAMPLES))
def test_example_files_exist(name):
    words = [w for w in _EXAMPLES[name].split() if w.startswith(("src/", "tests/"))]
    for w in words:
        assert glob.glob(str(ROOT / w)), f"{name}: {w} names no file"
