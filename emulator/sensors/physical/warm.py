"""Compile the numba kernels ahead: one `physical` scan of each kind of sensor that uses them.

numba compiles a kernel on its first call and keeps the machine code in an on-disk cache;
a cold cache costs a process 10–30 s at its first `physical` scan or plume crossing. The
container image and the test session call `compile_kernels()` once, so no daemon's first
scan (nor a timed test) pays for the compilation; a warm cache makes this cost about 1 s.
"""

from __future__ import annotations

from emulator.optics import World
from emulator.scene import load_scene
from emulator.sensors import configured_scans, create_sensor
from emulator.sensors.response import apply_model_override

# (bundled scene, sensor, time s): a multi-echo Hokuyo (standing, then on the moving robot), a single-echo
# Hokuyo and an LMS200 in a plume, a five-echo LMS511 with its fog filter; each instant has puffs in its beams
SCANS = (
    ("rescue", "utm", 30.0), ("rescue", "utm", 59.0), ("rescue", "urg", 30.0), ("rescue", "lms", 30.0),
    ("marulan", "lms5", 30.0),
)


def compile_kernels() -> None:
    """One streamed and one lone `physical` scan per entry of SCANS (both call paths)."""
    worlds: dict[str, tuple] = {}
    for scene_name, sensor_name, time_s in SCANS:
        if scene_name not in worlds:
            scene = apply_model_override(load_scene(scene_name), "physical")
            worlds[scene_name] = (scene, World(scene))
        scene, world = worlds[scene_name]
        sensor = create_sensor(scene, sensor_name, world)
        sensor.configured_scan(time_s)
        configured_scans(sensor, [time_s + index * sensor.configured_period_s for index in range(2)])
