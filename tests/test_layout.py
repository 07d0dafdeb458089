"""The house rules that keep the layout readable, checked on the source tree (DESIGN.md §1)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The library's modules: everything but the applications and ``python -m warptex``, which runs them.
LIBRARY = [p for d in ("warptex", "kernels") for p in (ROOT / d).rglob("*.py") if "apps" not in p.relative_to(ROOT).parts and p.name != "__main__.py"]


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


def _uses_apps(path: Path) -> bool:
    return any(name == "warptex.apps" or name.startswith("warptex.apps.") for name in _imports(path))


@pytest.mark.skipif(not (ROOT / "benchmarks").is_dir(), reason="benchmarks/ is not part of this checkout")
def test_benchmarks_do_not_import_the_applications():
    """Scenes the benchmarks share with the apps live in warptex.scenes, which anything may import."""
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "benchmarks").rglob("*.py") if _uses_apps(p)]
    assert offenders == []


def test_the_library_never_imports_the_applications():
    assert LIBRARY, "no library modules found"
    offenders = [str(p.relative_to(ROOT)) for p in LIBRARY if _uses_apps(p)]
    assert offenders == []


MAX_MODULE_LINES = 400


def test_no_module_of_the_library_is_longer_than_it_can_be_read():
    """A module over 400 lines mixes concerns (issue 32): split it by concern rather than grow it."""
    modules = [p for d in ("warptex", "kernels") for p in (ROOT / d).rglob("*.py")]
    assert modules, "no modules found"
    long = {str(p.relative_to(ROOT)): n for p in modules if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert long == {}
