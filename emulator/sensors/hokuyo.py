"""A simulated Hokuyo of any model in `hokuyo_models`: beams, timing and device values.

The URG-04LX's values come from the scene's preset (`urg_values`). The SCIP 2.2
units (docs/physical-model.md §6):

- under `physical`, the multi-echo receiver (`physical.multi_echo.echo_lists_at`
  with the model's `PULSED_RECEIVERS` entry): every echo within DMIN..DMAX,
  nearest first, with its intensity; `values` (what GD/MD send) is the first
  echo, or when none is in range the code for "too near" (an echo closer than
  DMIN) or "no object in range";
- under `formsma2011`, the paper's Hokuyo rule with the unit's own range and
  codes (`formsma2011.hokuyo_values`): one echo, its intensity the surface's
  reflectivity × cos(incidence) / (range / 2.5 m)² on the receiver's scale.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from emulator.optics import BeamHits, World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors import formsma2011
from emulator.sensors.hokuyo_models import URG_04LX, HokuyoModel
from emulator.sensors.mount import SensorMount, cast_moving
from emulator.sensors.physical.multi_echo import echo_lists_at, intensity_of, nearest_first
from emulator.sensors.physical.params import DEFAULT_PARAMS, PULSED_RECEIVERS
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant


def revolution_phase_ms(scene: Scene, name: str, model: HokuyoModel) -> int:
    """When sensor `name`'s revolutions complete, past each period: the i-th of a scene's n sensors of its
    model turns i × period / n (whole ms) behind the first. Real units are not powered on in step; a
    daemon serving many then sends their scans spread over the period instead of all at once, and
    daemons of a fleet, given the same scene, agree on every sensor's instants."""
    same = [spec.name for spec in scene.sensors if spec.model == model.name]
    return same.index(name) * int(round(model.period_s * 1000)) // len(same)


REFERENCE_RANGE_M = 2.5  # the receivers' reference target: white paper at 2.5 m


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
            return [Scan(self.name, self.model, t, self.angles_rad, row, "mm") for t, row in zip(times_s, values)]
        if not instants:
            return []
        first, echoes, strengths = self._echoes(hits, beams)
        values[:, self._valid] = first
        shape = (len(instants), model.steps, model.max_echoes)
        all_echoes, all_strengths = np.full(shape, -1, dtype=np.int64), np.full(shape, -1, dtype=np.int64)
        all_echoes[:, :, 0], all_strengths[:, :, 0] = values, 0  # outside AMIN..AMAX: the code, no intensity
        all_echoes[:, self._valid], all_strengths[:, self._valid] = echoes, strengths
        return [
            Scan(
                self.name, self.model, t, self.angles_rad, row, "mm", None, row_strengths[:, 0],
                row_echoes if model.max_echoes > 1 else None, row_strengths if model.max_echoes > 1 else None,
            )
            for t, row, row_echoes, row_strengths in zip(times_s, values, all_echoes, all_strengths)
        ]

    def _echoes(self, hits: Sequence[BeamHits], beams: Sequence[Beams]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K, N) single-echo values, (K, N, E) echoes and their intensities: each beam's first slot holds
        its value (a code when nothing is in range, intensity 0), further echoes nearest first, -1 after."""
        model, receiver = self.description, PULSED_RECEIVERS[self.model]
        if self.scene.model == "physical":
            lists = echo_lists_at(hits, beams, receiver, DEFAULT_PARAMS)
            millimetres = np.rint(np.nan_to_num(lists.ranges_m, nan=-1.0) * 1000.0).astype(np.int64)
            seen = np.isfinite(lists.ranges_m) & (millimetres >= model.min_value_mm) & (millimetres <= model.max_value_mm)
            too_near = (np.isfinite(lists.ranges_m) & (millimetres < model.min_value_mm)).any(axis=-1)
            echoes, strengths = nearest_first(seen, millimetres, lists.intensities(receiver))
            code = np.where(too_near, model.non_measurable, model.no_echo)
            first = np.where(echoes[..., 0] >= 0, echoes[..., 0], code)
        else:
            first = values_at_instants(formsma2011, "hokuyo_values", hits, beams, model).astype(np.int64)
            reflectivity = np.stack([hit.reflectivity * hit.cos_incidence for hit in hits])
            range_m = np.maximum(first / 1000.0, 0.1)
            power = np.nan_to_num(reflectivity) / (range_m / REFERENCE_RANGE_M) ** 2
            echoes = np.full((*first.shape, model.max_echoes), -1, dtype=np.int64)
            strengths = np.full_like(echoes, -1)
            strengths[..., 0] = np.where(first >= model.min_value_mm, intensity_of(power, receiver), 0)
        echoes[..., 0] = first
        strengths[..., 0] = np.maximum(strengths[..., 0], 0)
        return first, echoes, strengths

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
