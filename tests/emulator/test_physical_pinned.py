"""`physical` scans pinned: a set of scans of the bundled scenes, as the wire carries them (values,
intensities, every echo and its intensity), against those the model computed before its walks were
compiled (tests/emulator/data/physical_pinned.npz). A speed-up must change no scan by more than
one wire unit (floating-point reordering).

`python tests/emulator/test_physical_pinned.py` rewrites the reference: do it only for a deliberate
change of the physics (the plume integration's too), and say so in the commit. A speed-up is checked
the other way round: rewrite it with the change reverted, then run this test with it applied.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from emulator.bench.sections import dense_plume_scene, hokuyos_on_the_urgs_mount
from emulator.optics import World
from emulator.scene import load_scene
from emulator.sensors import create_sensor, lms200
from emulator.sensors.response import apply_model_override

REFERENCE = Path(__file__).parent / "data" / "physical_pinned.npz"
# (scene, sensor, first instant s, scans in one `scans` call): the multi-echo units on a moving mount in
# smoke (rescue, at its densest), on fixed mounts (marulan, railway), and the single-echo URG and LMS200
FIELDS = ("values", "intensities", "echoes", "echo_intensities")
CASES = (
    ("rescue", "utm", 2.0, 4),
    ("rescue", "utm", 15.8, 4),
    ("marulan", "lms5", 30.0, 4),
    ("marulan", "lms5", 47.0, 1),
    ("railway-hokuyos", "ust-10lx", 20.0, 4),
    ("rescue-hokuyos", "ust-20lx", 40.0, 2),
    ("rescue", "urg", 15.8, 4),
    ("marulan", "lms", 30.0, 2),
    ("railway-10k", "urg", 10.0, 2),
)


def _scene(label: str):
    if label == "railway-10k":
        scene = dense_plume_scene()
    elif label.endswith("-hokuyos"):
        scene = hokuyos_on_the_urgs_mount(load_scene(label.removesuffix("-hokuyos")))
    else:
        scene = load_scene(label)
    return apply_model_override(scene, "physical")


def pinned_scans(label: str, name: str, start_s: float, count: int) -> dict[str, np.ndarray]:
    """The case's scans, field → (count, ...) int32 (fields a model lacks are left out)."""
    scene = _scene(label)
    sensor = create_sensor(scene, name, World(scene))
    times = [start_s + j * sensor.configured_period_s for j in range(count)]
    if isinstance(sensor, lms200.LmsSensor):
        scans = sensor.scans(times, **lms200.configured_window(sensor.spec.options))
    else:
        scans = sensor.scans(times)
    found = {}
    for field in FIELDS:
        if getattr(scans[0], field) is not None:
            found[field] = np.stack([np.asarray(getattr(scan, field)) for scan in scans]).astype(np.int32)
    return found


def _key(case: tuple, field: str) -> str:
    label, name, start_s, count = case
    return f"{label}|{name}|{start_s}|{count}|{field}"


@pytest.mark.parametrize("case", CASES, ids=lambda case: f"{case[0]}-{case[1]}-{case[2]}")
def test_scans_match_the_pinned_reference_within_one_wire_unit(case):
    reference = np.load(REFERENCE)
    scans = pinned_scans(*case)
    assert sorted(scans) == sorted(field for field in FIELDS if _key(case, field) in reference.files)
    for field, values in scans.items():
        expected = reference[_key(case, field)]
        assert values.shape == expected.shape, field
        difference = np.abs(values.astype(np.int64) - expected)
        assert difference.max() <= 1, f"{field}: {np.count_nonzero(difference > 1)} values differ by more than 1"


def test_the_pinned_cases_exercise_echoes_through_smoke():
    """The reference holds what the cases are for: beams with several echoes, and smoke in front of walls."""
    reference = np.load(REFERENCE)
    echoes = reference[_key(CASES[1], "echoes")]
    several = (echoes[..., 1:] >= 0).any(axis=-1)
    assert several.mean() > 0.05
    assert (reference[_key(CASES[2], "echoes")][..., 1:] >= 0).any()


if __name__ == "__main__":
    REFERENCE.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCE, **{_key(case, f): v for case in CASES for f, v in pinned_scans(*case).items()})
    sys.exit(0)
