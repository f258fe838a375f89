"""A top-down map of the scene at one instant (`plot --map`): what a rescue team's floor plan would show.

Solids are their meshes' footprints, grey by height (floors lightest, walls
darkest); smoke regions are shaded orange by their density at the time asked
(relative to the densest the scene ever gets); plume particles alive at that
time are their collision boxes in purple; each moving body's whole trajectory
is a blue line with a dot where the body is at that time; the chosen sensor's
scan at that time is red points (green cross: the sensor), and the directions
whose beams returned an error code are teal ticks around it. With a span
(`plot --map --start T0 --end T1`: `draw_map(..., since_s=T0)` at T1) the
scene is drawn at its end and every scan of the sensor in it is drawn, each
beam from where the sensor was when it measured it: at most MAX_MAP_BEAMS
beams (1 000 000: 1300 scans of a URG-04LX), a longer span refused in one
line once its first scan is made, before the others. Axes in
metres with equal scale in x and y, a legend of what is drawn beside them;
`MapView.pixel` turns a world point into the pixel it is drawn at (the tests
read pixels back with it).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.errors import UserError
from emulator.plots.output import save_figure
from emulator.plots.waterfall import LMS_NO_RETURN_CODES, pyplot, span_scan_times
from emulator.scene import Pose, Scene, SceneObject, Shape
from emulator.scene.bodies import Body, BodyPoses, Frames, Keyframes
from emulator.scene.geometry import world_mesh
from emulator.scene.plumes import particles_at
from emulator.sensors import Scan, beam_times_s, create_sensor, hokuyo_model, ranges_m
from emulator.sensors.mount import SensorMount
from emulator.sensors.series import scan_series, scan_times

BACKGROUND_RGB = (1.0, 1.0, 1.0)
SMOKE_RGB = (1.0, 0.55, 0.1)
PLUME_RGB = (0.55, 0.3, 0.75)
TRAJECTORY_RGB = (0.1, 0.3, 0.9)
SCAN_RGB = (0.9, 0.05, 0.05)
SENSOR_RGB = (0.0, 0.6, 0.1)
ERROR_CODE_RGB = (0.0, 0.65, 0.75)
FLOOR_TOP_M = 0.1  # objects no higher than this are floors: drawn, but they do not set the map's extent
SOLID_DARKEST_AT_M = 2.0
MAX_SMOKE_ALPHA = 0.75
PLUME_ALPHA = 0.6
MARGIN_M = 1.0
TRAJECTORY_SAMPLES = 2000
# Beams a map draws at most (plot --map --start/--end: each a point or a tick): 1300 scans of a URG-04LX, 925 of a UTM-30LX.
MAX_MAP_BEAMS = 1_000_000
ERROR_TICKS = (0.025, 0.06)  # where an error code's tick runs from the sensor, in parts of the map's width
# The image's frame around the map, in pixels: tick labels left and below, the title above, the legend right.
FRAME_LEFT_PX, FRAME_BOTTOM_PX, FRAME_TOP_PX, FRAME_GAP_PX = 62, 44, 30, 12
LEGEND_WIDTH_PX = 250


def solid_grey(top_m: float) -> float:
    """Grey level of a solid whose top is at `top_m`: 0.85 for a floor down to 0.25 from 2 m up."""
    return 0.85 - 0.6 * float(np.clip(top_m / SOLID_DARKEST_AT_M, 0.0, 1.0))


def smoke_alpha(density: float, densest: float) -> float:
    """Opacity of a smoke region's shade: its density over the scene's densest, up to 0.75."""
    return 0.0 if densest <= 0 else MAX_SMOKE_ALPHA * float(np.clip(density / densest, 0.0, 1.0))


@dataclass(frozen=True)
class MapView:
    """The world rectangle the map shows and where it lies on the image: world point → pixel."""

    x_range: tuple[float, float]
    y_range: tuple[float, float]
    width_px: int  # the map's box on the image
    height_px: int
    left_px: int = 0  # the box's top-left corner on the image
    top_px: int = 0

    def pixel(self, x: float, y: float) -> tuple[int, int]:
        """(row, column) on the image of world point (x, y); row 0 is the top (largest y)."""
        column = (x - self.x_range[0]) / (self.x_range[1] - self.x_range[0]) * self.width_px
        row = (self.y_range[1] - y) / (self.y_range[1] - self.y_range[0]) * self.height_px
        return self.top_px + int(row), self.left_px + int(column)

    def inside(self, image: np.ndarray) -> np.ndarray:
        """The map's box cut out of the image (the frame, tick labels and legend left out)."""
        return image[self.top_px:self.top_px + self.height_px, self.left_px:self.left_px + self.width_px]


def map_box(width_px: int, height_px: int) -> tuple[int, int, int, int]:
    """(left, top, width, height) of the map on an image of that size: the frame's room taken
    off (the legend's shrinks on a narrow image)."""
    legend = min(LEGEND_WIDTH_PX, width_px // 3)
    width = max(width_px - FRAME_LEFT_PX - FRAME_GAP_PX - legend, 1)
    height = max(height_px - FRAME_TOP_PX - FRAME_BOTTOM_PX, 1)
    return FRAME_LEFT_PX, FRAME_TOP_PX, width, height


def sensor_poses_2d(scene: Scene, sensor: str, times_s: np.ndarray) -> np.ndarray:
    """A sensor's (x, y, yaw rad) in the world at each of `times_s` (on its body, if it rides one):
    the ground truth a SLAM path is compared with."""
    frames = SensorMount(scene, scene.sensor(sensor), BodyPoses(scene.bodies)).frames(times_s)
    rotations = frames.rotations
    return np.column_stack([frames.positions[:, 0], frames.positions[:, 1], np.arctan2(rotations[:, 1, 0], rotations[:, 0, 0])])


def body_frames(scene: Scene, body: str, times_s: np.ndarray) -> Frames:
    """Body `body`'s frames at `times_s` (the scene's trajectories)."""
    return BodyPoses(scene.bodies).frames(body, times_s)


def trajectory_times(body: Body) -> np.ndarray:
    """Instants covering a keyframed body's whole trajectory (empty for a live body or one that stays)."""
    if not isinstance(body.trajectory, Keyframes) or len(body.trajectory.times) == 0:
        return np.zeros(0)
    keyframes = body.trajectory.times
    return np.unique(np.concatenate([keyframes, np.linspace(keyframes[0], keyframes[-1], TRAJECTORY_SAMPLES)]))


@dataclass(frozen=True)
class _Footprint:
    triangles: np.ndarray  # (n, 3, 2)
    top_m: float


def _object_pose(scene: Scene, obj: SceneObject, time_s: float) -> Pose:
    """Where a solid is at `time_s`: its own pose, or its place on its body there."""
    if obj.body is None:
        return obj.pose
    return body_frames(scene, obj.body, np.array([time_s])).then(obj.pose).at(0)


def _footprint(shape: Shape, pose: Pose) -> _Footprint:
    mesh = world_mesh(shape, pose)
    return _Footprint(np.asarray(mesh.triangles)[:, :, :2], float(mesh.bounds[1][2]))


def _turn(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """> 0 when a → b → c turns left."""
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _outline(footprint: _Footprint) -> np.ndarray:
    """The convex hull (k, 2) of a footprint (Andrew's monotone chain): one polygon, so a translucent
    shade is even (triangles would darken or, antialiased, lighten where their edges meet)."""
    points = np.unique(np.round(footprint.triangles.reshape(-1, 2), 9), axis=0)
    if len(points) < 3:
        return points

    def chain(ordered: np.ndarray) -> list[np.ndarray]:
        hull: list[np.ndarray] = []
        for point in ordered:
            while len(hull) >= 2 and _turn(hull[-2], hull[-1], point) <= 0:
                hull.pop()
            hull.append(point)
        return hull

    lower, upper = chain(points), chain(points[::-1])
    return np.array(lower[:-1] + upper[:-1])


@dataclass(frozen=True)
class ScanOnMap:
    """A scan (or every scan of a span) in the world: its points, the beams that returned an error
    code (where each left from and its direction), and the sensor's pose (x, y, yaw) at the time
    stamp (a span's: at its end)."""

    points: np.ndarray  # (n, 2)
    error_origins: np.ndarray  # (k, 2)
    error_angles: np.ndarray  # (k,) rad, world frame
    pose: np.ndarray  # (3,)
    scans: int = 1


def _placed(scene: Scene, sensor: str, scan: Scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, error origins, error angles) of one scan in the world, each beam from the sensor's
    pose at the instant it was measured. Codes meaning "nothing in range" and a Hokuyo's steps
    outside its measurable area are neither points nor errors."""
    ranges = ranges_m(scan)
    beam_poses = sensor_poses_2d(scene, sensor, beam_times_s(scan))
    angles = np.asarray(scan.angles_rad, dtype=float) + beam_poses[:, 2]
    seen = ~np.isnan(ranges)
    points = beam_poses[seen, :2] + ranges[seen, None] * np.column_stack([np.cos(angles[seen]), np.sin(angles[seen])])
    hokuyo = hokuyo_model(scene.sensor(sensor).model)
    measurable = np.zeros(len(ranges), dtype=bool)
    measurable[hokuyo.valid_steps if hokuyo is not None else slice(None)] = True
    no_return = np.isin(np.asarray(scan.values), hokuyo.no_return_codes if hokuyo is not None else LMS_NO_RETURN_CODES)
    errors = ~seen & measurable & ~no_return
    return points, beam_poses[errors, :2], angles[errors]


def scan_points(scene: Scene, sensor: str, time_s: float) -> ScanOnMap:
    """The sensor's scan at `time_s` in the world (`_placed`)."""
    points, origins, angles = _placed(scene, sensor, create_sensor(scene, sensor).configured_scan(time_s))
    return ScanOnMap(points, origins, angles, sensor_poses_2d(scene, sensor, np.array([time_s]))[0])


def span_points(scene: Scene, sensor: str, start_s: float, end_s: float, max_beams: int = MAX_MAP_BEAMS) -> ScanOnMap:
    """Every scan of the sensor completed in [start_s, end_s] (on its scan period and phase, as
    `record` takes them) in the world, with the sensor's pose at `end_s`; none, or more than
    `max_beams` beams, is a UserError once the first scan is made, before the others."""
    device = create_sensor(scene, sensor)
    period_s, phase_s = device.configured_period_s, device.configured_phase_s
    head = scan_times(period_s, start_s, min(end_s, start_s + period_s), phase_s)  # one scan, if the span holds one
    if not len(head):
        raise UserError(f"no scan of {sensor} completes between --start {start_s:.10g} and --end {end_s:.10g} s")
    first = device.configured_scan(float(head[0]))
    times = span_scan_times(period_s, start_s, end_s, len(first.values), max_beams, sensor, "a map draws", phase_s)
    scans = itertools.chain([first], scan_series(device, times[1:]))
    placed = [_placed(scene, sensor, scan) for scan in scans]
    return ScanOnMap(np.vstack([p[0] for p in placed]), np.vstack([p[1] for p in placed]),
                     np.concatenate([p[2] for p in placed]), sensor_poses_2d(scene, sensor, np.array([end_s]))[0],
                     scans=len(times))


def _counted(count: int, noun: str) -> str:
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def _extent(parts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    points = np.vstack([p.reshape(-1, 2) for p in parts if p.size])
    return points.min(axis=0) - MARGIN_M, points.max(axis=0) + MARGIN_M


def _view(low: np.ndarray, high: np.ndarray, width_px: int, height_px: int) -> MapView:
    """Grow the shorter side so metres are square on the map's box."""
    left, top, box_width, box_height = map_box(width_px, height_px)
    span = high - low
    metres_per_px = max(span[0] / box_width, span[1] / box_height)
    centre = (low + high) / 2
    half = np.array([box_width, box_height]) * metres_per_px / 2
    return MapView((centre[0] - half[0], centre[0] + half[0]), (centre[1] - half[1], centre[1] + half[1]),
                   box_width, box_height, left, top)


def draw_map(
    scene: Scene, time_s: float, out: Path, *, sensor: str | None = None, since_s: float | None = None,
    width_px: int = 1200, height_px: int = 900, extra_points: np.ndarray | None = None,
    extra_paths: tuple[tuple[np.ndarray, tuple[float, float, float], str], ...] = (),
    title: str | None = None,
) -> MapView:
    """Draw the scene from above at `time_s` into `out` (PNG, or the format its suffix names);
    the view, for reading pixels back.

    With `since_s`, the sensor's scans are every one from `since_s` to `time_s`
    (`span_points`), not the one at `time_s`. `extra_points` (n, 2) are drawn like
    scan points (a SLAM map); `extra_paths` are (points (n, 2), rgb, label) lines
    (an estimated path)."""
    plt = pyplot()
    from matplotlib.collections import LineCollection, PolyCollection

    solids = [_footprint(obj.shape, _object_pose(scene, obj, time_s)) for obj in scene.objects]
    regions = [(_footprint(region.shape, region.pose), region.density) for region in scene.regions]
    particles = [particles_at(plume, scene.seed, index, time_s) for index, plume in enumerate(scene.plumes)]
    bodies = [body for body in scene.bodies if len(trajectory_times(body))]
    paths = [body_frames(scene, body.name, trajectory_times(body)).positions[:, :2] for body in bodies]
    here = [body_frames(scene, body.name, np.array([time_s])).positions[0, :2] for body in bodies]
    if sensor is None:
        scan = None
    else:
        scan = scan_points(scene, sensor, time_s) if since_s is None else span_points(scene, sensor, since_s, time_s)

    extent_parts = [f.triangles for f in solids if f.top_m > FLOOR_TOP_M] + [f.triangles for f, _ in regions]
    extent_parts += [p.centers[:, :2] for p in particles] + paths + [np.asarray(plume.source)[:2] for plume in scene.plumes]
    extent_parts += [np.asarray(spec.pose.position)[:2] for spec in scene.sensors if spec.body is None]
    if scan is not None:
        extent_parts.append(scan.pose[:2])
    if not any(part.size for part in extent_parts):
        extent_parts = [f.triangles for f in solids] or [np.zeros((1, 2))]
    view = _view(*_extent(extent_parts), width_px, height_px)

    dpi = 100
    figure = plt.figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi, facecolor=BACKGROUND_RGB)
    axes = figure.add_axes((view.left_px / width_px, 1 - (view.top_px + view.height_px) / height_px,
                            view.width_px / width_px, view.height_px / height_px))
    axes.set_xlim(*view.x_range)
    axes.set_ylim(*view.y_range)
    axes.set_xlabel("x (m)", labelpad=1)
    axes.set_ylabel("y (m)", labelpad=1)
    axes.tick_params(labelsize="small")
    legend = _Legend()
    for footprint in sorted(solids, key=lambda f: f.top_m):
        grey = solid_grey(footprint.top_m)
        axes.add_collection(PolyCollection(footprint.triangles, facecolors=(grey,) * 3, edgecolors=(grey,) * 3,
                                           linewidths=0.3, zorder=1))
    if solids:
        legend.patch((solid_grey(SOLID_DARKEST_AT_M),) * 3, "solids (darker = taller)")
    densest = max((max(v for _, v in density.keyframes) for _, density in regions), default=0.0)
    for footprint, density in regions:
        alpha = smoke_alpha(float(density.at(time_s)), densest)
        if alpha > 0:
            axes.add_collection(PolyCollection([_outline(footprint)], facecolors=(*SMOKE_RGB, alpha),
                                               edgecolors="none", zorder=2))
    if densest > 0:
        legend.patch((*SMOKE_RGB, MAX_SMOKE_ALPHA), f"smoke density (darkest: {densest:.3g})")
    for cloud in particles:
        boxes = [np.array([[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]])
                 for (x, y, _), h in zip(cloud.centers, cloud.half_sizes)]
        if boxes:
            axes.add_collection(PolyCollection(boxes, facecolors=(*PLUME_RGB, PLUME_ALPHA), edgecolors="none", zorder=3))
    if scene.plumes:
        legend.patch((*PLUME_RGB, PLUME_ALPHA), "plume particles")
    for path, position in zip(paths, here):
        axes.plot(path[:, 0], path[:, 1], color=TRAJECTORY_RGB, linewidth=2, zorder=4)
        axes.plot(*position, "o", color=TRAJECTORY_RGB, markersize=9, zorder=6)
    if bodies:
        legend.line(TRAJECTORY_RGB, "trajectories (dot: now)", marker="o")
    for path, rgb, label in extra_paths:
        axes.plot(path[:, 0], path[:, 1], color=rgb, linewidth=1.5, zorder=5)
        legend.line(rgb, label)
    if extra_points is not None and len(extra_points):
        axes.plot(extra_points[:, 0], extra_points[:, 1], ".", color=SCAN_RGB, markersize=2, zorder=5)
        legend.line(SCAN_RGB, "map points", marker=".", linestyle="none")
    if scan is not None:
        axes.plot(scan.points[:, 0], scan.points[:, 1], ".", color=SCAN_RGB, markersize=3, zorder=7)
        axes.plot(*scan.pose[:2], "+", color=SENSOR_RGB, markersize=14, markeredgewidth=3, zorder=8)
        width_m = view.x_range[1] - view.x_range[0]
        directions = np.column_stack([np.cos(scan.error_angles), np.sin(scan.error_angles)])
        ticks = np.stack([scan.error_origins + ERROR_TICKS[0] * width_m * directions,
                          scan.error_origins + ERROR_TICKS[1] * width_m * directions], axis=1)
        axes.add_collection(LineCollection(ticks, colors=[ERROR_CODE_RGB], linewidths=1.0, zorder=7))
        scans = "" if since_s is None else f" ({_counted(scan.scans, 'scan')})"
        legend.line(SCAN_RGB, f"scan points of {sensor}{scans}", marker=".", linestyle="none")
        legend.line(SENSOR_RGB, sensor, marker="+", linestyle="none", markeredgewidth=2)
        legend.line(ERROR_CODE_RGB, f"error codes ({_counted(len(scan.error_angles), 'beam')})")
    if title is None:
        title = f"{scene.name}: t = {time_s:g} s" + (f", scan of {sensor}" if sensor else "")
        if since_s is not None and sensor:
            title = f"{scene.name}: t = {time_s:g} s, scans of {sensor} from {since_s:g} s"
    axes.set_title(title, fontsize=10, loc="left")
    if legend.handles:
        figure.legend(handles=legend.handles, loc="upper left", fontsize="small", frameon=False,
                      bbox_to_anchor=((view.left_px + view.width_px + FRAME_GAP_PX / 2) / width_px, 1 - view.top_px / height_px))
    try:
        save_figure(figure, out, dpi=dpi, facecolor=BACKGROUND_RGB)
    finally:
        plt.close(figure)
    return view


class _Legend:
    """The legend's entries, in the order things are drawn."""

    def __init__(self) -> None:
        self.handles: list = []

    def patch(self, colour: tuple[float, ...], label: str) -> None:
        from matplotlib.patches import Patch

        self.handles.append(Patch(facecolor=colour, edgecolor="none", label=label))

    def line(self, colour: tuple[float, ...], label: str, **style: object) -> None:
        from matplotlib.lines import Line2D

        self.handles.append(Line2D([], [], color=colour, label=label, **style))
