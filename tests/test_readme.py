"""The README's promises: two set-up commands, CI runs the test one; the docs' schema table is current."""

from __future__ import annotations

import re
from pathlib import Path

from overbound.io.schema import schema_markdown

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
EPOCH_TABLE = (ROOT / "docs" / "epoch-table.md").read_text(encoding="utf-8")


def _setup_commands() -> list[str]:
    block = re.search(r"```bash\n(.*?)```", README, re.S)
    assert block and README.index(block.group(0)) < 40, "the README must open with its set-up commands"
    return [ln for ln in block.group(1).splitlines() if ln.strip()]


def test_readme_opens_with_exactly_two_commands():
    demo, tests = _setup_commands()
    assert "pip install ." in demo and demo.endswith("overbound demo")
    assert 'pip install ".[test]"' in tests and tests.endswith("pytest")


def test_ci_runs_the_readme_test_command():
    _, tests = _setup_commands()
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert tests in ci.splitlines()


def test_setup_commands_make_and_use_a_virtual_environment():
    """A stock Debian/Ubuntu Python refuses ``pip install`` outside one (externally-managed-environment)."""
    for command in _setup_commands():
        assert command.startswith("python3 -m venv .venv && .venv/bin/python -m pip install")


def test_docs_schema_table_is_generated_from_schema():
    inside = EPOCH_TABLE.split("<!-- schema:begin -->")[1].split("<!-- schema:end -->")[0]
    assert inside.strip() == schema_markdown().strip()
