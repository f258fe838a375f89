"""Response models: how a scene's `model` preset turns `BeamHits` into device values.

A preset is a module `emulator.sensors.<preset>` defining

    urg_values(hits: BeamHits, beams: Beams) -> np.ndarray   # int values per beam (mm or code < 20)
    lms_values(hits: BeamHits, beams: Beams, unit: str, *, field_bits=13) -> np.ndarray   # int values (unit or
                                                      # the codes 8183..8191 moved to the top of the field_bits field)

so a new preset needs no registration: naming it in the scene selects it.
A preset may also define `urg_values_at` / `lms_values_at(hits, beams, ...)`
taking lists (one entry per instant) and returning (K, N) values: several
instants in one pass, each row equal to the single-instant call (the
instants' beams may differ: a sensor on a moving body casts new ones each scan)
(`values_at_instants` falls back to one call per instant).
`Beams` gives a model everything beyond the hits (scene, sensor, world to
cast more rays, the beams' geometry and time).
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Sequence

import numpy as np

from emulator.errors import UserError
from emulator.optics import BeamHits, World
from emulator.scene.model import Scene, SensorSpec

PRESET_MODULES = {"formsma2011": "emulator.sensors.formsma2011", "physical": "emulator.sensors.physical.preset"}


@dataclass(frozen=True)
class Beams:
    """The beams of one scan: sensor-frame angles (N,), world origins and unit directions (N, 3).

    A sensor that does not move leaves `rotations` None: `sensor.pose` places
    every beam. A moving one gives each beam's sensor → world rotation
    (N, 3, 3) and instant `beam_times_s` (N,), so a model casting more rays
    (sub-rays of a footprint) casts them from where the sensor was.
    """

    scene: Scene
    sensor: SensorSpec
    world: World
    time_s: float
    angles_rad: np.ndarray
    origins: np.ndarray
    directions: np.ndarray
    rotations: np.ndarray | None = None
    beam_times_s: np.ndarray | None = None


def apply_model_override(scene: Scene, model: str | None) -> Scene:
    """`scene` with its smoke/sensor model replaced (a CLI `--model`); None keeps it."""
    if model is None:
        return scene
    if model not in PRESET_MODULES:
        raise UserError(f"unknown smoke model {model!r} (known: {', '.join(PRESET_MODULES)})")
    return dataclasses.replace(scene, model=model)


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


def values_at_instants(
    model: ModuleType, name: str, hits: Sequence[BeamHits], beams: Sequence[Beams], *args: Any, **keywords: Any
) -> np.ndarray:
    """`model.<name>` (`urg_values` or `lms_values`) at several instants, (K, N): in one pass where
    the preset offers `<name>_at`, else one instant after another."""
    batched = getattr(model, f"{name}_at", None)
    if batched is not None:
        return np.asarray(batched(hits, beams, *args, **keywords))
    single = getattr(model, name)
    return np.stack([np.asarray(single(h, b, *args, **keywords)) for h, b in zip(hits, beams)])

