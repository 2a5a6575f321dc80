"""Core and plugins stay headless (README "Layout": napari's import-linter rule)."""
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


def _contracts() -> dict:
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return {c["name"]: c for c in cfg["tool"]["importlinter"]["contracts"]}


def test_core_never_imports_plugins_contract():
    """Core finds steps through entry points by name (core.registry), never by import."""
    c = _contracts()["core never imports a plugin"]
    assert c["type"] == "forbidden"
    assert c["source_modules"] == ["pointspro.core"] and c["forbidden_modules"] == ["pointspro.plugins"]
    assert c.get("ignore_imports", []) == ["pointspro.core.cli -> pointspro.app.main"]


def test_every_plugin_package_is_in_the_independence_contract():
    """A new plugin is independent of the others too (a third party would copy it alone)."""
    c = next(c for c in _contracts().values() if c["type"] == "independence")
    packages = {f"pointspro.plugins.{p.name}" for p in (ROOT / "plugins").iterdir()
                if (p / "__init__.py").is_file()}
    assert set(c["modules"]) == packages


def test_every_package_folder_is_in_the_wheel():
    """`pip install .` builds a wheel from pyproject's explicit package list; an editable install (the
    README's) finds every folder anyway, so a forgotten one broke only a real install — as
    core.profiles, core.tolerance and core.uncertainty did (a batch on a clean machine failed at
    probe_radius with ModuleNotFoundError)."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(cfg["tool"]["setuptools"]["packages"])
    folders = {"pointspro." + ".".join(p.parent.relative_to(ROOT).parts)
               for top in ("core", "plugins", "app") for p in (ROOT / top).rglob("__init__.py")
               if "__pycache__" not in p.parts}
    assert folders - listed == set(), "missing from [tool.setuptools] packages"
    assert listed - folders == set(), "listed but not a package folder"
