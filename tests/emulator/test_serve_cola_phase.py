"""CoLa units of one scene power on at different instants, as real ones do: the daemon's units and the
simulated sensors (what `record` samples) agree on each one's scan instants."""

from __future__ import annotations

import asyncio
from pathlib import Path

from emulator.daemon.service import Daemon
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.sensors.sick_cola import power_on_phase_ms

SCENE = """
[scene]
name = "six-colas"
model = "formsma2011"
seed = 3
[[objects]]
name = "wall"
box = { size = [0.2, 12.0, 3.0] }
position = [8.0, 0.0, 1.5]
"""
SENSOR = '[[sensors]]\nname = "{name}"\nmodel = "{model}"\nposition = [0.0, {y}, 0.5]\nendpoints = ["tcp:127.0.0.1:0"]\n'


def six_units(tmp_path: Path):
    sensors = [(f"tim{i}", "tim571") for i in range(4)] + [(f"lms{i}", "lms111") for i in range(2)]
    path = tmp_path / "six.toml"
    path.write_text(SCENE + "".join(SENSOR.format(name=name, model=model, y=0.3 * i)
                                    for i, (name, model) in enumerate(sensors)))
    return load_scene(path)


def test_each_cola_unit_powers_on_at_its_golden_ratio_fraction_of_its_period(tmp_path: Path) -> None:
    scene = six_units(tmp_path)
    phases = {spec.name: power_on_phase_ms(scene, spec.name) for spec in scene.sensors}
    # i·0.618… mod 1 of 66.67 ms (TiM571, 15 Hz) and of 20 ms (LMS111, 50 Hz)
    assert phases == {"tim0": 0, "tim1": 41, "tim2": 15, "tim3": 56, "lms0": 9, "lms1": 1}
    assert power_on_phase_ms(six_units(tmp_path), "tim3") == 56  # the same scene, the same instants


def test_the_daemons_units_and_the_sensors_agree_on_the_phase(tmp_path: Path) -> None:
    scene = six_units(tmp_path)
    daemon = Daemon(scene)
    loop = asyncio.new_event_loop()
    try:
        daemon.start(loop, lambda ready: None)
        units = {session.device.unit for session in daemon.sessions}
        power_on = sorted(unit.power_on_s for unit in units)
    finally:
        daemon.close()
        loop.close()
    expected = sorted(create_sensor(scene, spec.name).configured_phase_s for spec in scene.sensors)
    assert len(units) == 6 and power_on == expected == sorted(power_on_phase_ms(scene, s.name) / 1000 for s in scene.sensors)
    assert len(set(power_on)) == 6
