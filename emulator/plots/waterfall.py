"""Scans over time and the smoke along the beams, and the waterfall figure (paper Fig. 3, 5, 10).

`sensor_series` computes what a plot shows: every scan of a sensor between two
times, plus the smoke its beams crossed at each scan. `plot` caps a span at
MAX_PLOT_BEAMS beams (6 000 000: 880 s of a URG-04LX, 139 s of a UTM-30LX): a
longer span is refused in one line once its first scan is made, before the
others, so a huge `--end` never takes memory without bound. `draw_waterfall` draws a
waterfall (time down, angle across as seen from behind the sensor, darker =
shorter, red = error code) with the smoke level over time beside it.

Camera saturation is shown for scenes with smoke regions, from the mean
density along the beams by `s = s0·exp(−c·density)` (docs/smoke-model.md §3). That
curve is an assumption fitted to the paper's single published point
(density 0.0028 ↔ saturation 0.14); every figure says so.

matplotlib is an optional extra: `pip install '.[plot]'`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from emulator.errors import UserError
from emulator.optics import World
from emulator.plots.output import save_figure
from emulator.scene import Scene
from emulator.sensors import Scan, create_sensor, hokuyo_model, ranges_m
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.series import scan_count, scan_series, scan_times

SATURATION_CLEAR = 0.8
SATURATION_PER_DENSITY = math.log(0.8 / 0.14) / 0.0028  # ≈ 622 per density unit
SATURATION_NOTE = "camera saturation s = 0.8·exp(−622·density): an assumption fitted to 0.0028 ↔ 0.14"

# The beams a waterfall draws at most (plot --start/--end): 8797 scans of a URG-04LX (880 s), 5550 of a UTM-30LX
# (139 s), 16620 of an LMS200 at 0.5° (443 s). About 55 bytes a beam (the series, and the image as float RGBA:
# matplotlib's own copies of a uint8 or RGB image took twice that): plot's whole process peaked at 480 MB at the cap.
MAX_PLOT_BEAMS = 6_000_000
LMS_CAST_RANGE_M = 80.0
# Codes that mean "nothing within range", shaded as the far end, not as errors.
LMS_NO_RETURN_CODES = (8183, 8191)

ERROR_RGB = (0.86, 0.10, 0.10)
NO_RETURN_RGB = (0.86, 0.92, 1.0)


def saturation(density: np.ndarray | float) -> np.ndarray:
    """Assumed camera saturation of the reference target seen through `density` (docs/smoke-model.md §3)."""
    return SATURATION_CLEAR * np.exp(-SATURATION_PER_DENSITY * np.asarray(density, dtype=float))


@dataclass(frozen=True)
class SensorSeries:
    """A sensor's scans over time (n scans × m beams) and the smoke its beams crossed.

    `ranges_m` is NaN for every code; `no_return` marks codes meaning nothing in
    range; `errors` the other codes. `mean_density` is ∫density ds / beam length
    averaged over the beams (d); `plume_range_m` (n × m) the distance to the
    first plume particle before the beam's solid hit (inf if none).
    """

    sensor: str
    model: str
    unit: str
    times_s: np.ndarray
    angles_rad: np.ndarray
    values: np.ndarray
    ranges_m: np.ndarray
    no_return: np.ndarray
    errors: np.ndarray
    mean_density: np.ndarray
    plume_range_m: np.ndarray
    has_regions: bool
    has_plumes: bool
    has_camera_reference: bool = False  # the scene's run had a camera on a reference target

    @property
    def in_plume(self) -> np.ndarray:
        """Beams whose first obstacle is a plume particle (n × m)."""
        return np.isfinite(self.plume_range_m)

    @property
    def plume_share(self) -> np.ndarray:
        """Fraction of the beams meeting a plume particle, per scan."""
        return self.in_plume.mean(axis=1)

    @property
    def saturation(self) -> np.ndarray:
        return saturation(self.mean_density)

    @property
    def max_range_m(self) -> float:
        hokuyo = hokuyo_model(self.model)
        if hokuyo is not None:
            return hokuyo.max_range_m
        return 8.183 if self.unit == "mm" else 81.83


def span_scan_times(
    period_s: float, start_s: float, end_s: float, beams: int, max_beams: int, sensor_name: str, what: str,
    phase_s: float = 0.0,
) -> np.ndarray:
    """`scan_times(period_s, start_s, end_s, phase_s)` of a span of at most `max_beams` beams (scans of
    `beams` each), or a UserError naming --end and the latest that fits (`what` draws them), counted
    before any time is made: a huge --end costs nothing."""
    max_scans = max(1, max_beams // beams)
    count = scan_count(period_s, start_s, end_s, phase_s)
    if count > max_scans:
        latest_s = scan_times(period_s, start_s, start_s + max_scans * period_s, phase_s)[max_scans - 1]
        raise UserError(f"--start {start_s:.10g} to --end {end_s:.10g} holds {count} scans of {sensor_name}: {what} "
                        f"at most {max_beams} beams, {max_scans} of its {beams}-beam scans (--end {latest_s:.10g} "
                        "at the latest from this --start); plot a shorter span")
    return scan_times(period_s, start_s, end_s, phase_s)


def sensor_series(
    scene: Scene, sensor_name: str, start_s: float, end_s: float,
    progress: Callable[[Iterator[Scan], int], Iterator[Scan]] | None = None, max_beams: int | None = None,
) -> SensorSeries:
    """Every scan of the sensor in [start_s, end_s] and the smoke along its beams at each;
    `progress(scans, count)` may wrap the scans as they are computed (a progress bar). With
    `max_beams` (`plot`: MAX_PLOT_BEAMS), a span of more beams is a UserError once its first scan
    is made; each scan is kept only as its row of the arrays (27 bytes a beam)."""
    world = World(scene)
    sensor = create_sensor(scene, sensor_name, world=world)
    spec = scene.sensor(sensor_name)
    period_s = sensor.configured_period_s
    head = scan_times(period_s, start_s, min(end_s, start_s + 2 * period_s))  # two scans, if the span holds two
    if len(head) < 2:
        raise UserError(f"--start {start_s} to --end {end_s} holds fewer than two scans of {sensor_name}")
    hokuyo = hokuyo_model(spec.model)
    columns = hokuyo.valid_steps if hokuyo is not None else slice(None)  # a Hokuyo's measurable area
    first = sensor.configured_scan(float(head[0]))  # how many beams a row has
    angles = np.asarray(first.angles_rad)[columns]
    if max_beams is None:
        times = scan_times(period_s, start_s, end_s)
    else:
        times = span_scan_times(period_s, start_s, end_s, len(angles), max_beams, sensor_name, "a waterfall draws")
    computed = itertools.chain([first], scan_series(sensor, times[1:]))
    scans = progress(computed, len(times)) if progress is not None else computed
    cast_range_m = hokuyo.max_range_m if hokuyo is not None else LMS_CAST_RANGE_M
    fixed_rays = None if sensor.mount.moving else scan_plane_rays(sensor.mount.fixed_spec.pose, angles)
    mean_density = np.zeros(len(times))
    values = np.empty((len(times), len(angles)), dtype=np.int64)
    ranges = np.empty((len(times), len(angles)))
    plume_range = np.empty((len(times), len(angles)))
    for i, (time_s, scan) in enumerate(zip(times, scans)):
        values[i] = np.asarray(scan.values)[columns]
        ranges[i] = ranges_m(scan)[columns]
        # a sensor on a moving body: the smoke along its beams from where it is at the scan's time stamp
        rays = fixed_rays or scan_plane_rays(sensor.mount.frames(np.array([time_s])).at(0), angles)
        hits = world.cast(*rays, cast_range_m, float(time_s))
        mean_density[i] = float(np.mean(hits.region_optical_path / hits.beam_end_m))
        plume_range[i] = hits.plume_hit_range_m
    is_code = np.isnan(ranges)
    no_return = np.isin(values, hokuyo.no_return_codes if hokuyo is not None else LMS_NO_RETURN_CODES) & is_code
    return SensorSeries(
        sensor=spec.name, model=spec.model, unit=first.unit, times_s=times, angles_rad=angles,
        values=values, ranges_m=ranges, no_return=no_return, errors=is_code & ~no_return,
        mean_density=mean_density, plume_range_m=plume_range,
        has_regions=bool(scene.regions), has_plumes=bool(scene.plumes),
        has_camera_reference=scene.camera_reference and bool(scene.regions),
    )


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend, or a UserError saying how to install it."""
    try:
        import matplotlib
    except ImportError:
        raise UserError("plotting needs matplotlib: pip install 'lrf-emulator[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


NEAREST_GREY, FARTHEST_GREY = 0.08, 0.95


def _rgb(ranges_m: np.ndarray, no_return: np.ndarray, errors: np.ndarray, max_range_m: float) -> np.ndarray:
    fraction = np.clip(np.nan_to_num(ranges_m, nan=0.0) / max_range_m, 0.0, 1.0)
    shade = NEAREST_GREY + (FARTHEST_GREY - NEAREST_GREY) * fraction
    image = np.repeat(shade[:, :, None], 3, axis=2)
    image[no_return] = NO_RETURN_RGB
    image[errors] = ERROR_RGB
    return image


def waterfall_rgb(series: SensorSeries) -> np.ndarray:
    """(n, m, 3) image: grey by range (darker = shorter), red for errors, pale for no return."""
    return _rgb(series.ranges_m, series.no_return, series.errors, series.max_range_m)


IMAGE_BLOCK_ROWS = 1024


def waterfall_rgba(series: SensorSeries) -> np.ndarray:
    """`waterfall_rgb` as matplotlib draws it, made IMAGE_BLOCK_ROWS scans at a time: each colour
    truncated to bytes (x · 255) and back to float32, opaque. 16 bytes a beam, and matplotlib draws
    it without a copy (from float64 RGB or uint8 it made float64 RGBA and more); the same pixels."""
    image = np.empty((*series.ranges_m.shape, 4), dtype=np.float32)
    image[:, :, 3] = 1.0
    for low in range(0, len(image), IMAGE_BLOCK_ROWS):
        rows = slice(low, low + IMAGE_BLOCK_ROWS)
        rgb = _rgb(series.ranges_m[rows], series.no_return[rows], series.errors[rows], series.max_range_m)
        image[rows, :, :3] = np.divide((rgb * 255).astype(np.uint8), 0xFF, dtype=np.float32)
    return image


def _range_colour_bar(figure: Any, bar_axes: Any, max_range_m: float) -> None:
    """The range each grey stands for, nearest (darkest) at the bottom."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    greys = LinearSegmentedColormap.from_list("range", [(NEAREST_GREY,) * 3, (FARTHEST_GREY,) * 3])
    figure.colorbar(ScalarMappable(Normalize(0.0, max_range_m), greys), cax=bar_axes, label="range (m)")


def draw_waterfall(series: SensorSeries, out: Path, *, width_px: int = 1200, height_px: int = 800, title: str = "") -> None:
    """Write the waterfall (PNG, or the format `out` names) of exactly width_px × height_px pixels."""
    plt = pyplot()
    from matplotlib.patches import Patch

    dpi = 100
    side = series.has_regions + series.has_camera_reference + series.has_plumes
    figure = plt.figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    # margins in pixels, whatever the image's size: room for the labels (two lines below) and the note
    figure.subplots_adjust(left=70 / width_px, right=1 - 20 / width_px, bottom=72 / height_px, top=1 - 32 / height_px)
    # the waterfall, its range colour bar, room for the bar's labels, then the side panels
    grid = figure.add_gridspec(1, 3 + side, width_ratios=[3, 0.08, 0.22] + [1] * side, wspace=0.12)
    axes = figure.add_subplot(grid[0, 0])
    degrees = np.degrees(series.angles_rad)
    axes.imshow(
        waterfall_rgba(series), aspect="auto", interpolation="nearest",
        extent=(degrees[0], degrees[-1], series.times_s[-1], series.times_s[0]),
    )
    axes.set_xlim(degrees.max(), degrees.min())  # left of the plot = the sensor's left
    axes.set_xlabel("beam angle (°, sensor frame; + = left)")
    axes.set_ylabel("time (s)")
    axes.set_title(title or f"{series.sensor} ({series.model}): darker = shorter range")
    axes.legend(
        handles=[Patch(color=ERROR_RGB, label="error code"), Patch(color=NO_RETURN_RGB, label="no return / beyond max")],
        loc="lower left", fontsize="small", framealpha=0.9,
    )
    _range_colour_bar(figure, figure.add_subplot(grid[0, 1]), series.max_range_m)
    column = 3
    if series.has_regions:
        density_axes = figure.add_subplot(grid[0, column], sharey=axes)
        density_axes.plot(series.mean_density * 1000.0, series.times_s, color="tab:blue")
        density_axes.set_xlabel("mean density\nalong beams (10⁻³ d)")
        density_axes.tick_params(labelleft=False)
        column += 1
    if series.has_camera_reference:
        saturation_axes = figure.add_subplot(grid[0, column], sharey=axes)
        saturation_axes.plot(series.saturation, series.times_s, color="tab:orange")
        saturation_axes.axvline(0.14, color="grey", linestyle="--", linewidth=0.8)
        saturation_axes.set_xlim(0.0, SATURATION_CLEAR + 0.05)
        saturation_axes.set_xlabel("camera saturation\n(assumed curve)")
        saturation_axes.tick_params(labelleft=False)
        column += 1
    if series.has_plumes:
        plume_axes = figure.add_subplot(grid[0, column], sharey=axes)
        plume_axes.plot(series.plume_share * 100.0, series.times_s, color="tab:green")
        plume_axes.set_xlabel("beams meeting\na plume (%)")
        plume_axes.tick_params(labelleft=False)
    if series.has_camera_reference:
        figure.text(0.01, 0.005, SATURATION_NOTE, fontsize="x-small", color="dimgrey")
    try:
        save_figure(figure, out, dpi=dpi)
    finally:
        plt.close(figure)
