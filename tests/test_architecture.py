"""Core and plugins stay headless (DESIGN "Lessons from the anchors": napari's import-linter rule)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from .conftest import ROOT


def test_import_linter_contracts_hold():
    exe = Path(sys.executable).parent / "lint-imports"
    res = subprocess.run([str(exe), "--no-cache", "--config", str(ROOT / "pyproject.toml")], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "broken" in res.stdout and "0 broken" in res.stdout


def test_no_qt_and_no_float32_computation_in_core_and_plugins():
    qt = re.compile(r"^\s*(from|import)\s+(PySide6|PyQt5|PyQt6|pyvistaqt|qtpy)\b", re.M)
    offenders = []
    for folder in ("core", "plugins"):
        for py in (ROOT / folder).rglob("*.py"):
            text = py.read_text(encoding="utf-8")
            if qt.search(text):
                offenders.append(str(py))
    assert offenders == []


def test_steps_never_print_or_exit():
    bad = []
    for py in (ROOT / "plugins").rglob("*.py"):
        text = py.read_text(encoding="utf-8")
        if re.search(r"^\s*print\(|sys\.exit\(", text, re.M):
            bad.append(str(py))
    assert bad == []
