"""Puts `tests/` on the import path so every test can import `support` (tests/support/)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import pytest


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels() -> None:
    """numba's kernels compiled (or loaded from its cache) once, before any test: on a fresh clone the
    first `physical` scan compiles for 10–30 s, which no daemon's first scan or timed test should pay."""
    from emulator.sensors.physical.warm import compile_kernels

    compile_kernels()
