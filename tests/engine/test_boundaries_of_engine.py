"""The engine imports nothing of the service layers (STYLE.md, architecture rules)."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FORBIDDEN = [
    "app", "worker", "web", "pydantic", "celery", "redis", "viser", "fastapi", "sqlalchemy",
]

BLOCKER = """
import importlib.abc, sys, pkgutil, importlib
FORBIDDEN = {forbidden!r}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in FORBIDDEN:
            raise ImportError('engine must not import ' + name)
        return None
sys.meta_path.insert(0, Block())
import engine
for info in pkgutil.walk_packages(engine.__path__, 'engine.'):
    importlib.import_module(info.name)
print('imported', len(sys.modules))
"""


@pytest.mark.slow
def test_engine_imports_no_service_layer():
    code = BLOCKER.format(forbidden=FORBIDDEN)
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
