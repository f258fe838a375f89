"""The CoLa SICKs (TiM5xx/TiM7xx, LMS1xx, LMS5xx): beam geometry, mirror timing, echoes and RSSI.

Device angles run from the model's start (-45° or -5°) to its stop (225° or
185°), 90° straight ahead: the sensor-frame angle is the device angle − 90°.
The mirror turns once per scan, counter-clockwise; a scan completes (its
time) when it reaches the stop angle, so the beam at device angle a was
measured (stop − a) / 360° of a period earlier. Each beam's echoes are
distance counts on the wire (mm, or 2 mm on the LMS5xx), nearest first, 0
never: a beam without an echo has none in the list (-1). The models' figures
come from scene.sick_models (docs/cola.md cites them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from emulator.optics import BeamHits, PreparedBeams, World
from emulator.scene.model import Scene, SensorSpec
from emulator.scene.sick_models import ANGLE_TICKS_PER_DEG, FREQUENCY_TICKS_PER_HZ, MODELS, SickModel
from emulator.sensors.mount import SensorMount, cast_moving
from emulator.sensors.physical.multi_echo import echo_lists_at, intensity_of, nearest_first
from emulator.sensors.physical.params import DEFAULT_PARAMS, PULSED_RECEIVERS
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant

# The single-echo presets give LMS-style values in mm with error codes at the top of a field this
# wide; 17 bits (131 m) hold every model's range, so codes never collide with distances.
FIELD_BITS = 17
FIELD_CODES_FROM = (1 << FIELD_BITS) - 9
REFERENCE_RANGE_M = 2.5  # the receivers' reference target: white paper at 2.5 m
GOLDEN_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0


def device_angles_deg(model: SickModel, resolution_ticks: int) -> np.ndarray:
    """The field's device angles at a resolution: 811 from -45° to 225° at 0.3333° (a 1/3° grid)."""
    count = model.beam_count(resolution_ticks)
    return np.linspace(model.start_deg, model.stop_deg, count)


def beam_offsets_s(model: SickModel, device_angles: np.ndarray, period_s: float) -> np.ndarray:
    """When each beam is measured relative to the scan's time (≤ 0): the mirror reaches the stop angle last."""
    offsets = -(model.stop_deg - np.asarray(device_angles, dtype=float)) / 360.0 * period_s
    offsets.flags.writeable = False
    return offsets


def power_on_phase_ms(scene: Scene, name: str) -> int:
    """When CoLa unit `name` powered on, in whole ms past simulated time 0 (less than its configured period):
    the i-th CoLa unit of the scene (scene order, any model) at the fraction i·φ mod 1 of its period
    (φ = 0.618…, the golden ratio's). Real units are not switched on together; a daemon serving many then
    sends their telegrams spread over time rather than all at one instant, units of different periods
    rarely coincide, and every daemon given the scene agrees on each unit's scan instants."""
    units = [spec for spec in scene.sensors if spec.model in MODELS]
    index = [spec.name for spec in units].index(name)
    period_ms = 1000.0 * FREQUENCY_TICKS_PER_HZ / configured_request(units[index].options)["frequency_ticks"]
    return int((index * GOLDEN_FRACTION) % 1.0 * period_ms)


def configured_request(options: Mapping[str, Any]) -> dict[str, Any]:
    """The `scan` keywords for the scan configuration the scene's options select."""
    return {
        "frequency_ticks": int(round(float(options["scan_frequency_hz"]) * FREQUENCY_TICKS_PER_HZ)),
        "resolution_ticks": int(round(float(options["resolution_deg"]) * ANGLE_TICKS_PER_DEG)),
        "fog_filter": bool(options.get("fog_filter", False)),
    }


@dataclass(frozen=True)
class _Window:
    angles_rad: np.ndarray
    offsets_s: np.ndarray
    prepared: PreparedBeams | None


class ColaSensor:
    """A simulated CoLa SICK: `scan(time_s, frequency_ticks=, resolution_ticks=, fog_filter=)`."""

    def __init__(self, scene: Scene, spec: SensorSpec, world: World) -> None:
        self.scene, self.spec, self.world = scene, spec, world
        self.name = spec.name
        self.model = spec.model
        self.sick = MODELS[spec.model]
        self._response = response_model(scene.model)
        self.mount = SensorMount(scene, spec, world.bodies)
        self._fixed_spec = self.mount.fixed_spec
        self._windows: dict[tuple[int, int], _Window] = {}
        self.configured_phase_s = power_on_phase_ms(scene, spec.name) / 1000  # scans complete at phase + k · period

    @property
    def period_s(self) -> float:
        return self.configured_period_s

    def _window(self, frequency_ticks: int, resolution_ticks: int) -> _Window:
        key = (frequency_ticks, resolution_ticks)
        if key not in self._windows:
            device_angles = device_angles_deg(self.sick, resolution_ticks)
            angles_rad = np.radians(device_angles - 90.0)
            angles_rad.flags.writeable = False
            prepared = None
            if not self.mount.moving:
                origins, directions = self.mount.fixed_rays(angles_rad)
                prepared = self.world.prepare(origins, directions, self.sick.max_range_m)
            offsets = beam_offsets_s(self.sick, device_angles, FREQUENCY_TICKS_PER_HZ / frequency_ticks)
            self._windows[key] = _Window(angles_rad, offsets, prepared)
        return self._windows[key]

    def _casts(self, window: _Window, instants: list[float]) -> list[tuple[BeamHits, Beams]]:
        prepared = window.prepared
        if prepared is None:
            return cast_moving(self.world, self.scene, self.spec, self.mount, window.angles_rad, window.offsets_s,
                               instants, self.sick.max_range_m)
        casts = []
        for time_s in instants:
            beam_times = time_s + window.offsets_s
            hits = self.world.cast_prepared(prepared, time_s, beam_times)
            beams = Beams(self.scene, self._fixed_spec, self.world, time_s, window.angles_rad, prepared.origins,
                          prepared.directions, beam_times_s=beam_times if self.world.moving else None)
            casts.append((hits, beams))
        return casts

    def scan(self, time_s: float, **request: Any) -> Scan:
        return self.scans((time_s,), **request)[0]

    def scans(
        self, times_s: Sequence[float], *, frequency_ticks: int | None = None, resolution_ticks: int | None = None,
        fog_filter: bool | None = None,
    ) -> list[Scan]:
        """The whole field at each of `times_s`: every echo (distance counts) and its intensity;
        `values` is the first echo as DIST1 carries it (0: none). What is not given is the scene's
        configuration (`configured_request`)."""
        configured = configured_request(self.spec.options)
        frequency_ticks = configured["frequency_ticks"] if frequency_ticks is None else frequency_ticks
        resolution_ticks = configured["resolution_ticks"] if resolution_ticks is None else resolution_ticks
        fog_filter = configured["fog_filter"] if fog_filter is None else fog_filter
        if not self.sick.offers(frequency_ticks, resolution_ticks):
            raise ValueError(f"{self.model} offers no scan at {frequency_ticks / 100:g} Hz, {resolution_ticks / 1e4:g}°")
        window = self._window(frequency_ticks, resolution_ticks)
        instants = [simulated_instant(t) for t in times_s]
        casts = self._casts(window, instants)
        if not casts:
            return []
        hits, beams = zip(*casts)
        echoes, powers = self._echoes(hits, beams, fog_filter)
        scans = []
        for t, row, power in zip(times_s, echoes, powers):
            first = np.where(row[:, 0] >= 0, row[:, 0], 0)
            first_power = np.where(row[:, 0] >= 0, power[:, 0], 0)
            scans.append(Scan(self.name, self.model, t, window.angles_rad, first, "mm", None, first_power, row, power))
        return scans

    def _echoes(self, hits: Sequence[BeamHits], beams: Sequence[Beams], fog_filter: bool) -> tuple[np.ndarray, np.ndarray]:
        """Echo counts and intensities (K, N, E). Under `physical`: the multi-echo receiver's echo list
        (its threshold, pulse separation, fog filter). Under another preset (`formsma2011`: the paper's
        Sick rule, a plume in the beam is an obstacle): its single echo as echo 1, its intensity from the
        surface's reflectivity, incidence and range on the receiver's scale."""
        sick, receiver = self.sick, PULSED_RECEIVERS[self.model]
        if self.scene.model == "physical":
            lists = echo_lists_at(hits, beams, receiver, DEFAULT_PARAMS, fog_filter=fog_filter)
            in_range = np.isfinite(lists.ranges_m) & (lists.ranges_m >= sick.min_range_m) & (lists.ranges_m <= sick.max_range_m)
            counts = np.rint(np.where(in_range, lists.ranges_m, 0.0) * 1000.0 / sick.distance_scale).astype(np.int64)
            echoes, powers = nearest_first(in_range, counts, lists.intensities(receiver))
            return echoes, powers
        millimetres = values_at_instants(self._response, "lms_values", hits, beams, "mm", field_bits=FIELD_BITS)
        millimetres = millimetres.astype(np.int64)
        min_mm, max_mm = sick.min_range_m * 1000.0, sick.max_range_m * 1000.0
        seen = (millimetres < FIELD_CODES_FROM) & (millimetres >= min_mm) & (millimetres <= max_mm)
        counts = np.rint(millimetres / sick.distance_scale).astype(np.int64)
        reflectivity = np.stack([hit.reflectivity * hit.cos_incidence for hit in hits])
        range_m = np.maximum(millimetres / 1000.0, 0.1)
        power = np.nan_to_num(reflectivity) / (range_m / REFERENCE_RANGE_M) ** 2
        shape = (*millimetres.shape, sick.echoes)
        echoes = np.full(shape, -1, np.int64)
        powers = np.full(shape, -1, np.int64)
        echoes[..., 0] = np.where(seen, counts, -1)
        powers[..., 0] = np.where(seen, intensity_of(power, receiver), -1)
        return echoes, powers

    def configured_scan(self, time_s: float) -> Scan:
        """The scan the scene's options select (`configured_request`), at `time_s`."""
        return self.scan(time_s, **configured_request(self.spec.options))

    @property
    def configured_period_s(self) -> float:
        return FREQUENCY_TICKS_PER_HZ / configured_request(self.spec.options)["frequency_ticks"]


DENSE_BEAMS = 1000  # a scan with more beams is streamed DENSE_BATCH scans per job
DENSE_BATCH = 2


def stream_batch(options: Mapping[str, Any], model: str) -> int | None:
    """DENSE_BATCH for a scan of more than DENSE_BEAMS beams (an LMS511 at 0.1667°: 1141), else None
    (the daemon's default). Its scans cost ~10-20 ms under `physical`: a batch of 8 took longer than
    the 1.5 periods it is started ahead, and every 8th scan went out up to 80 ms late."""
    request = configured_request(options)
    return DENSE_BATCH if MODELS[model].beam_count(request["resolution_ticks"]) > DENSE_BEAMS else None


def angle_offsets_s(model_name: str, angles_rad: np.ndarray, period_s: float) -> np.ndarray:
    """`beam_offsets_s` of a scan's sensor-frame angles."""
    return beam_offsets_s(MODELS[model_name], np.degrees(np.asarray(angles_rad)) + 90.0, period_s)


def ranges_m(model_name: str, values: np.ndarray) -> np.ndarray:
    """Metres per distance count, NaN where the beam had no echo (0 on the wire, -1 in an echo list)."""
    values = np.asarray(values)
    return np.where(values > 0, values * MODELS[model_name].distance_scale / 1000.0, np.nan)
