"""A simulated Hokuyo of any model in `hokuyo_models`: beams, timing and device values.

The URG-04LX's values come from the scene's preset (`urg_values`). The SCIP 2.2
units get theirs from the preset's `hokuyo_values` when it has one, else from
the paper's Hokuyo rule (`formsma2011.hokuyo_values`) with the unit's own range
and codes: one echo, no intensity.
"""

from __future__ import annotations

from types import ModuleType
from typing import Sequence

import numpy as np

from emulator.optics import BeamHits, World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors import formsma2011
from emulator.sensors.hokuyo_models import URG_04LX, HokuyoModel
from emulator.sensors.mount import SensorMount, cast_moving
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant


def revolution_phase_ms(scene: Scene, name: str, model: HokuyoModel) -> int:
    """When sensor `name`'s revolutions complete, past each period: the i-th of a scene's n sensors of its
    model turns i × period / n (whole ms) behind the first. Real units are not powered on in step; a
    daemon serving many then sends their scans spread over the period instead of all at once, and
    daemons of a fleet, given the same scene, agree on every sensor's instants."""
    same = [spec.name for spec in scene.sensors if spec.model == model.name]
    return same.index(name) * int(round(model.period_s * 1000)) // len(same)


def hokuyo_preset(preset: ModuleType) -> ModuleType:
    """The module giving the SCIP 2.2 units' values: the preset if it models them, else formsma2011."""
    return preset if hasattr(preset, "hokuyo_values") or hasattr(preset, "hokuyo_values_at") else formsma2011


class HokuyoSensor:
    """A simulated Hokuyo: `scan(time_s)` gives one value per step 0..steps−1."""

    def __init__(self, scene: Scene, spec: SensorSpec, world: World, model: HokuyoModel) -> None:
        self.scene, self.spec, self.world = scene, spec, world
        self.description = model
        self.model = model.name
        self.name = spec.name
        self.period_s = self.configured_period_s = model.period_s
        self.angles_rad = model.step_angles_rad()
        self._valid = model.valid_steps
        self._valid_angles = self.angles_rad[self._valid]
        self._valid_offsets = model.step_offsets_s()[self._valid]
        self.mount = SensorMount(scene, spec, world.bodies)
        self._fixed_spec = self.mount.fixed_spec
        self._prepared = None
        if not self.mount.moving:
            self._origins, self._directions = self.mount.fixed_rays(self._valid_angles)
            self._prepared = world.prepare(self._origins, self._directions, model.max_range_m)  # fixed geometry never moves
        self._response = response_model(scene.model)
        self.configured_phase_s = revolution_phase_ms(scene, spec.name, model) / 1000

    def scan(self, time_s: float) -> Scan:
        """The scan stamped at simulated time `time_s` (each beam evaluated at the instant it is measured)."""
        return self.scans((time_s,))[0]

    def configured_scan(self, time_s: float) -> Scan:
        """The same as `scan`: a Hokuyo has one scan (its window is chosen by the protocol)."""
        return self.scan(time_s)

    def scans(self, times_s: Sequence[float]) -> list[Scan]:
        """`scan` at each of `times_s`, computed together: a preset that can (`physical`)
        shares each pass among them, which costs far less per scan."""
        instants = [simulated_instant(t) for t in times_s]
        casts = self._casts(instants)
        hits, beams = zip(*casts) if casts else ((), ())
        model = self.description
        values = np.full((len(instants), model.steps), model.no_echo, dtype=np.int64)
        if model is URG_04LX:
            values[:, self._valid] = values_at_instants(self._response, "urg_values", hits, beams)
        else:
            values[:, self._valid] = values_at_instants(hokuyo_preset(self._response), "hokuyo_values", hits, beams, model)
        return [Scan(self.name, self.model, t, self.angles_rad, row, "mm") for t, row in zip(times_s, values)]

    def _casts(self, instants: list[float]) -> list[tuple[BeamHits, Beams]]:
        """The valid steps' hits at each instant, each beam at the instant its step is measured."""
        reach = self.description.max_range_m
        if self._prepared is None:
            return cast_moving(self.world, self.scene, self.spec, self.mount, self._valid_angles, self._valid_offsets, instants, reach)
        casts = []
        for time_s in instants:
            beam_times = time_s + self._valid_offsets
            hits = self.world.cast_prepared(self._prepared, time_s, beam_times)
            beams = Beams(
                self.scene, self._fixed_spec, self.world, time_s, self._valid_angles, self._origins, self._directions,
                beam_times_s=beam_times if self.world.moving else None,  # sub-rays then meet moving solids at their instants
            )
            casts.append((hits, beams))
        return casts
