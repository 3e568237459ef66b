"""The seams between the packages, checked on the source (issue 24).

- The analysis folder's file names are spelled once, in ``worker.contract.AnalysisFolder``:
  app, worker and web name none of them.
- The worker reaches the engine by a plain import (no module named in a string).
- The engine's I/O layer imports nothing of the stages above it.
- The packages import along one chain, app -> worker -> engine and web -> app.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: File names inside an analysis folder (worker.contract.AnalysisFolder).
FOLDER_NAMES = re.compile(
    r"^(status\.json|result\.json|tasks\.json|prepare\.npz|stages|cancel|heartbeat|attempts)$"
    r"|^candidates-|\.npz$"
)


def _sources(*packages: str) -> list[Path]:
    return sorted(
        p for pkg in packages for p in (REPO / pkg).rglob("*.py")
        if "migrations" not in p.parts
    )  # fmt: skip


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (they may describe the layout)."""
    out = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            value = body[0].value
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                out.add(id(value))
    return out


def folder_names_spelled(path: Path) -> list[str]:
    """Every string constant (f-string parts too, docstrings not) naming a folder file."""
    tree = ast.parse(path.read_text())
    docs = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if FOLDER_NAMES.search(node.value):
                found.append(f"{path}:{node.lineno}: {node.value!r}")
    return found


def test_the_check_sees_a_re_spelled_name(tmp_path):
    bad = tmp_path / "probe.py"
    bad.write_text('"""Docs may say status.json."""\n'
                   'P = W / "stages" / f"candidates-{i}-of-{n}.npz"\n')  # fmt: skip
    assert len(folder_names_spelled(bad)) == 3  # "stages", "candidates-", ".npz"
    bad.write_text('R = Path("w") / "result.json"\nURL = "/analyses/{id}/cancel"\n')
    assert len(folder_names_spelled(bad)) == 1


def test_app_worker_and_web_do_not_re_spell_the_analysis_folder():
    contract = REPO / "worker" / "contract.py"
    found = [
        hit for p in _sources("app", "worker", "web") if p != contract
        for hit in folder_names_spelled(p)
    ]  # fmt: skip
    assert found == [], "use worker.contract.AnalysisFolder:\n" + "\n".join(found)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.add(node.module)
    return out


def test_the_worker_imports_the_engine_it_runs():
    assert "engine" in _imports(REPO / "worker" / "jobs.py") or any(
        m.startswith("engine.pipeline") for m in _imports(REPO / "worker" / "jobs.py")
    )
    for p in _sources("worker"):
        assert "import_module" not in p.read_text(), f"{p}: a module named in a string"


@pytest.mark.parametrize("layer", ["engine/io"])
def test_engine_io_imports_no_stage(layer):
    for p in sorted((REPO / layer).rglob("*.py")):
        above = {
            m for m in _imports(p)
            if m.startswith(("engine.stages", "engine.pipeline", "engine.synth"))
        }  # fmt: skip
        assert not above, f"{p.relative_to(REPO)} imports {sorted(above)}"


#: The only package arrows there may be: app -> worker -> engine, web -> app (issue 24).
#: The app reaches the engine through ``worker.engine_surface``, the web pages reach the worker
#: and the engine through ``app.web_surface``.
ALLOWED = {"app": {"worker"}, "web": {"app"}, "worker": {"engine"}, "engine": set()}


def arrows_off_the_chain(package: str, sources: list[Path]) -> list[str]:
    """``path: module`` for every import of a sibling package that the chain does not allow."""
    others = set(ALLOWED) - {package} - ALLOWED[package]
    return [
        f"{p}: {m}" for p in sources for m in sorted(_imports(p)) if m.split(".")[0] in others
    ]  # fmt: skip


def test_the_chain_check_sees_a_short_cut(tmp_path):
    bad = tmp_path / "page.py"
    bad.write_text("from engine.report import ONE_CAMERA_NOTE\nimport worker.contract\n"
                   "from app.web_surface import BONE_NAMES\n")  # fmt: skip
    assert arrows_off_the_chain("web", [bad]) == [
        f"{bad}: engine.report", f"{bad}: worker.contract"
    ]
    assert arrows_off_the_chain("app", [bad]) == [f"{bad}: engine.report"]


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_imports_follow_the_chain(package):
    """app -> worker -> engine, web -> app, nothing else: no arrow goes back up, and none
    skips a layer (the web pages join the app through declared entry points, not imports)."""
    found = arrows_off_the_chain(package, _sources(package))
    assert found == [], "import through the surface modules:\n" + "\n".join(found)
