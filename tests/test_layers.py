"""The package's layers (docs/architecture.md): a module imports only from its own layer or lower ones.

Every ``from overbound... import`` and ``import overbound...`` of every module is read from its source
(top level or inside a function; imports under ``if TYPE_CHECKING:`` are annotations only and do not
count), so that an upward import, even a lazy one, fails here with the file and line.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "overbound"

#: Layer of each top-level module or package of overbound, lowest first.
LAYERS = {
    0: {"__init__", "_allocator", "jsontext", "numbers", "output", "services"},
    1: {"io"},
    2: {"stats"},
    3: {"methods"},
    4: {"sbas"},
    5: {"verdict"},
    6: {"analysis", "campaign", "campaign_confidence", "campaign_parametric", "campaign_tail"}
    | {"simulate", "sbas_map", "sbas_network"},
    7: {"report"},
    8: {"cli", "__main__"},
}
RANK = {name: rank for rank, names in LAYERS.items() for name in names}


def _top(module: str) -> str:
    """``overbound.io.ems`` -> ``io``; ``overbound`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Line numbers of the bodies of ``if TYPE_CHECKING:`` blocks."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for stmt in node.body:
                lines.update(range(stmt.lineno, (stmt.end_lineno or stmt.lineno) + 1))
    return lines


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported overbound module) of every run-time import of ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_checking_lines(tree)
    out = []
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "overbound":
            out.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "overbound"]
    return out


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if "data" not in p.relative_to(SRC).parts)


def test_every_module_has_a_layer() -> None:
    tops = {p.relative_to(SRC).parts[0].removesuffix(".py") for p in _modules()}
    assert tops <= set(RANK), f"modules without a layer in tests/test_layers.py: {sorted(tops - set(RANK))}"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_imports_from_a_higher_layer(path: Path) -> None:
    me = path.relative_to(SRC).parts[0].removesuffix(".py")
    upward = [f"{path.relative_to(SRC)}:{line} imports {mod} (layer {RANK[_top(mod)]} > {RANK[me]})"
              for line, mod in _imports(path) if RANK[_top(mod)] > RANK[me]]  # fmt: skip
    assert not upward, "\n".join(upward)


def test_the_check_sees_a_lazy_upward_import(tmp_path: Path) -> None:
    """The reader of imports finds one inside a function and ignores one under TYPE_CHECKING."""
    src = tmp_path / "m.py"
    src.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from overbound.analysis import Analysis\n"
        "def f():\n    from overbound.report.figures import new_figure\n"
    )
    assert _imports(src) == [(5, "overbound.report.figures")]
