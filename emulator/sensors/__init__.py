"""The simulated sensors: `create_sensor(scene, name)`, `ranges_m(scan)` and `beam_times_s(scan)`."""

from __future__ import annotations

import numpy as np

from emulator.errors import UserError
from emulator.optics import World
from emulator.scene.model import Scene, SensorSpec
from emulator.scene import sick_models
from emulator.sensors import lms200, sick_cola, urg04lx
from emulator.sensors.hokuyo import HokuyoSensor
from emulator.sensors.hokuyo_models import HOKUYO_MODELS, HokuyoModel
from emulator.sensors.lms200 import LmsSensor
from emulator.sensors.sick_cola import ColaSensor
from emulator.sensors.scan import Scan
from emulator.sensors.urg04lx import UrgSensor

Sensor = HokuyoSensor | LmsSensor | ColaSensor
MODELS = (*HOKUYO_MODELS, lms200.MODEL, *sick_models.NAMES)

__all__ = [
    "HOKUYO_MODELS", "ColaSensor", "HokuyoModel", "HokuyoSensor", "LmsSensor", "MODELS", "Scan", "Sensor", "UrgSensor",
    "beam_times_s", "configured_scans", "create_sensor", "hokuyo_model", "ranges_m", "stream_batch",
]  # fmt: skip


def hokuyo_model(model: str) -> HokuyoModel | None:
    """The description of Hokuyo model `model`, None for a scanner of another make."""
    return HOKUYO_MODELS.get(model)


def create_sensor(scene: Scene, name: str, world: World | None = None) -> Sensor:
    """The scene's sensor `name`. Pass one `World` to share it between a scene's sensors."""
    known = [spec.name for spec in scene.sensors]
    if name not in known:
        raise UserError(f"no sensor named {name!r} in scene {scene.name!r} (known: {', '.join(known) or 'none'})")
    spec = scene.sensor(name)
    world = world if world is not None else World(scene)
    if spec.model == urg04lx.MODEL:
        return UrgSensor(scene, spec, world)
    if spec.model in HOKUYO_MODELS:
        return HokuyoSensor(scene, spec, world, HOKUYO_MODELS[spec.model])
    if spec.model == lms200.MODEL:
        return LmsSensor(scene, spec, world)
    if spec.model in sick_models.MODELS:
        return ColaSensor(scene, spec, world)
    raise UserError(f"sensor {name!r}: unknown model {spec.model!r} (known: {', '.join(MODELS)})")


def configured_scans(sensor: Sensor, times_s: list[float]) -> list[Scan]:
    """The scene-configured scan at each of `times_s`, computed together as a daemon streams them (an LMS200's
    window from its scene options; the others' `scans` default to their scene configuration)."""
    if isinstance(sensor, LmsSensor):
        return sensor.scans(times_s, **lms200.configured_window(sensor.spec.options))
    return sensor.scans(times_s)


def stream_batch(spec: SensorSpec) -> int | None:
    """Scans of a steady stream a daemon computes per job, where the sensor needs fewer than its
    default (None): a scan so dense that a whole batch would not be done one stride ahead of its first
    scan (the LMS5xx at its finest)."""
    return sick_cola.stream_batch(spec.options, spec.model) if spec.model in sick_models.MODELS else None


def beam_times_s(scan: Scan) -> np.ndarray:
    """The simulated instant each of the scan's values was measured (its mirror's timing: before the
    stamp for a URG-04LX or LMS200, which stamp the completed scan; after it for the SCIP 2.2 Hokuyos,
    which stamp the sweep's first step)."""
    if scan.model in HOKUYO_MODELS:
        return scan.time_s + HOKUYO_MODELS[scan.model].angle_offsets_s(scan.angles_rad)
    if scan.model == lms200.MODEL:
        return scan.time_s + lms200.angle_offsets_s(scan.angles_rad)
    if scan.model in sick_models.MODELS:  # at the model's power-on scan frequency
        frequency_ticks = sick_models.MODELS[scan.model].default[0]
        return scan.time_s + sick_cola.angle_offsets_s(scan.model, scan.angles_rad, 100.0 / frequency_ticks)
    raise ValueError(f"unknown sensor model {scan.model!r}")


def ranges_m(scan: Scan) -> np.ndarray:
    """The scan's values in metres, NaN where the device reported an error code."""
    if scan.model in HOKUYO_MODELS:
        return HOKUYO_MODELS[scan.model].ranges_m(scan.values)
    if scan.model == lms200.MODEL:
        return lms200.ranges_m(scan.values, scan.unit)
    if scan.model in sick_models.MODELS:
        return sick_cola.ranges_m(scan.model, scan.values)
    raise ValueError(f"unknown sensor model {scan.model!r}")
