"""Response models: how a scene's `model` preset turns `BeamHits` into device values.

A preset is a module `emulator.sensors.<preset>` defining

    urg_values(hits: BeamHits, beams: Beams) -> np.ndarray   # int values per beam (mm or code < 20)
    lms_values(hits: BeamHits, beams: Beams, unit: str) -> np.ndarray   # int values (unit or 8183..8191)

so a new preset needs no registration: naming it in the scene selects it.
`Beams` gives a model everything beyond the hits (scene, sensor, world to
cast more rays, the beams' geometry and time).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from emulator.errors import UserError
from emulator.optics import World
from emulator.scene.model import Scene, SensorSpec

PRESET_MODULES = {"formsma2011": "emulator.sensors.formsma2011", "physical": "emulator.sensors.physical"}


@dataclass(frozen=True)
class Beams:
    """The beams of one scan: sensor-frame angles (N,), world origins and unit directions (N, 3)."""

    scene: Scene
    sensor: SensorSpec
    world: World
    time_s: float
    angles_rad: np.ndarray
    origins: np.ndarray
    directions: np.ndarray


def response_model(preset: str) -> ModuleType:
    """The module implementing `preset`; a UserError names the known ones."""
    if preset not in PRESET_MODULES:
        raise UserError(f"unknown smoke model {preset!r} (known: {', '.join(PRESET_MODULES)})")
    try:
        return importlib.import_module(PRESET_MODULES[preset])
    except ModuleNotFoundError as error:
        if error.name != PRESET_MODULES[preset]:
            raise
        raise UserError(f"smoke model {preset!r} is not available in this version") from error
