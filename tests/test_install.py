"""The install: `make serve` sets up the runtime only, `make test` adds the test and plot extras,
and building the package prints no setuptools deprecation warning."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def make_dry_run(target: str, venv: Path) -> list[str]:
    """The commands `make TARGET` would run on a machine with no venv yet."""
    result = subprocess.run(["make", "-n", "--no-print-directory", "-C", str(ROOT), target, f"VENV={venv}"], capture_output=True, text=True,
                            timeout=30, check=True)
    return result.stdout.splitlines()


def pip_installs(commands: list[str]) -> list[str]:
    return [line for line in commands if " install " in line and "--upgrade pip" not in line]


def test_make_serve_installs_the_runtime_only_and_make_test_adds_the_extras(tmp_path: Path) -> None:
    venv = tmp_path / "fresh-venv"
    serve = make_dry_run("serve", venv)
    assert pip_installs(serve) == [f"{venv}/bin/pip install --quiet -e ."]
    assert serve[-1].startswith(f"{venv}/bin/lrf-emulator serve")
    test = make_dry_run("test", venv)
    assert pip_installs(test) == [f"{venv}/bin/pip install --quiet -e .",
                                  f"{venv}/bin/pip install --quiet -e '.[test,plot]'"]
    assert test[-1] == f"{venv}/bin/python -m pytest -q"


def test_building_the_package_prints_no_setuptools_warning(tmp_path: Path) -> None:
    """pip builds a copy of the source (the tree itself stays free of build/ and egg-info)."""
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    for folder in ("emulator", "protocols", "scenes"):
        shutil.copytree(ROOT / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__"))
    result = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--verbose", "--wheel-dir", str(tmp_path / "dist"), str(source)],
        capture_output=True, text=True, timeout=600,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    assert list((tmp_path / "dist").glob("lrf_emulator-*.whl"))
    assert "project.license" not in output and "License classifiers are deprecated" not in output, output[-3000:]
    assert "SetuptoolsDeprecationWarning" not in output and "BuildBackendWarning" not in output, output[-3000:]
