"""The browser view (`serve --view HOST:PORT`): the live scene in 3D, built on viser.

viser serves its bundled web client and runs its own server thread; all of
it lives in the view's own process (`process.py`), at a lowered priority, so
its work (serialising point clouds and scene updates, the web socket) never
holds the daemon's GIL or takes a core from its loop. The daemon sends it the
world and the latest scans at most `process.UPDATE_RATE_HZ` times a second, and only
while a browser is connected.

Drawn: the solids in their materials' colours; smoke regions as translucent
volumes whose opacity follows their density now (`recording/scene_look.py`);
plume particles where they are now; each sensor's frame and its latest scan
as points coloured by range (near yellow, far blue), with the beams that gave
an error code as red marks on a small ring around the sensor (no echo is not
marked). The panel (present when the daemon's control API is on) has a
density slider per region, an emitting toggle per plume, the clock's speed
and pause, and a gizmo per live body; each acts through the control API
(`control_client.py`), the same way in as any other client.

viser serves the page and its web socket on one port through `websockets`,
whose HTTP parser takes GET alone: any other method had the connection
closed without a word (and a traceback on the daemon's stderr). The view's
process answers it `405 Method Not Allowed` with `Allow: GET` instead
(`answer_other_methods`).
"""

from __future__ import annotations

import http
import re
import socket
from collections.abc import Generator
from typing import Any, Callable, Mapping

import numpy as np
import rich
import viser
import websockets.asyncio.server
from websockets.protocol import CONNECTING
from websockets.server import ServerProtocol

from emulator.recording.laserscan import values_to_ranges
from emulator.recording.scene_look import (
    SMOKE_RGB,
    material_rgb,
    quaternion_xyzw,
    range_rgb,
    smoke_alpha,
    thickness_m,
)
from emulator.recording.world_snapshot import SceneSnapshots, WorldSnapshot
from emulator.scene.bodies import Live
from emulator.scene.model import Box, Cylinder, Pose, Scene, Shape, Sphere
from emulator.scene.geometry import shape_mesh
from emulator.sensors import hokuyo_model
from emulator.sensors.published import published
from emulator.sensors.scan import Scan
from emulator.view.control_client import ControlClient, ControlError
from emulator.view.process import PortTaken

MAX_TRAJECTORY_POINTS = 600
TRAJECTORY_RGB = (255, 140, 0)
INITIAL_CAMERA = ((-5.0, -7.0, 7.0), (3.0, 0.0, 0.0))  # behind and above the origin, where scenes put the robot
ERROR_RING_M = 0.3
ERROR_RGB = (230, 20, 20)
SCAN_POINT_SIZE = 0.05
GIZMO_SCALE_M = 1.2  # arrow length; its plane handles sit at 0.14..0.37 of it
LMS_RANGE_FOR_COLOUR_M = 20.0
MAX_RANGE_FOR_COLOUR_M = 20.0  # a long-range Hokuyo's 30 or 60 m would paint a room in one colour


def _wxyz(rotation_deg: tuple[float, float, float]) -> tuple[float, float, float, float]:
    x, y, z, w = quaternion_xyzw(rotation_deg)
    return (w, x, y, z)


def rotation_deg_of(wxyz: np.ndarray) -> list[float]:
    """Roll, pitch, yaw (degrees, R = Rz·Ry·Rx) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in wxyz)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return [float(np.degrees(angle)) for angle in (roll, pitch, yaw)]


def scan_points(scan: Scan, pose: Pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points of the scan's echoes with their colours, and the red marks of its error beams
    (its measured beams only: `published`)."""
    scan = published(scan)
    ranges = values_to_ranges(scan.values, scan.model, scan.unit)
    angles = np.asarray(scan.angles_rad, dtype=float)
    local = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    rotation, origin = pose.rotation_matrix(), np.asarray(pose.position, dtype=float)
    echo = np.isfinite(ranges)
    error = np.isnan(ranges) | (ranges == -np.inf)
    hits = origin + (local[echo] * ranges[echo, None]) @ rotation.T
    marks = origin + (local[error] * ERROR_RING_M) @ rotation.T
    hokuyo = hokuyo_model(scan.model)
    reach = min(hokuyo.max_range_m, MAX_RANGE_FOR_COLOUR_M) if hokuyo is not None else LMS_RANGE_FOR_COLOUR_M
    colours = range_rgb(ranges[echo], reach)
    return hits.astype(np.float32), colours, marks.astype(np.float32)


def _port_free(host: str, port: int) -> bool:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            return False
    return True


_METHOD = re.compile(rb"[!#$%&'*+.^_`|~0-9A-Za-z-]+")  # an HTTP method: a token (RFC 9110)
_METHOD_SEEN_WITHIN = 64  # bytes of the request line within which its method's end (a space) is looked for


class _ViewServerProtocol(ServerProtocol):
    """viser's WebSocket server protocol, but a request whose method is not GET is answered 405 with
    `Allow: GET` (websockets' parser refused it with no response at all). Everything else is
    websockets' own: the method is read from the bytes received, which are left for its parser."""

    def parse(self) -> Generator[None]:
        if self.state is CONNECTING:
            method = yield from self._method()
            if method is not None and method != b"GET":
                shown = method.decode("ascii")
                response = self.reject(http.HTTPStatus.METHOD_NOT_ALLOWED,
                                       f"{shown} is not allowed: the browser view serves its page to GET only\n")
                response.headers["Allow"] = "GET"
                if method == b"HEAD":
                    response.body = b""  # a HEAD answer has no body (Content-Length says what it would be)
                self.send_response(response)  # then end of stream, and the rest is discarded
                yield
                return
        yield from super().parse()

    def _method(self) -> Generator[None, None, bytes | None]:
        """The request line's method once received, without consuming it; None if it is not one."""
        reader = self.reader
        while True:
            end = reader.buffer.find(b" ", 0, _METHOD_SEEN_WITHIN)
            if end >= 0:
                method = bytes(reader.buffer[:end])
                return method if _METHOD.fullmatch(method) else None
            if len(reader.buffer) >= _METHOD_SEEN_WITHIN or b"\n" in reader.buffer or reader.eof:
                return None  # websockets' parser refuses it as before
            yield


def answer_other_methods() -> None:
    """Make the `websockets` servers of this process (the view's own: viser's) answer a method other
    than GET with 405 and `Allow: GET`. viser gives no way to pass a protocol of our own, so the name
    its server looks up is replaced; nothing else in the view's process serves through websockets."""
    if websockets.asyncio.server.ServerProtocol is ServerProtocol:
        websockets.asyncio.server.ServerProtocol = _ViewServerProtocol  # type: ignore[misc]


class BrowserView:
    """The viser server, the scene drawn into it, and its panel; `update` redraws the world.

    It runs in the view's own process (`process.py`), which feeds it."""

    def __init__(self, scene: Scene, listen: tuple[str, int], on_watchers: Callable[[int], None]) -> None:
        host, port = listen
        if port != 0 and not _port_free(host, port):
            raise PortTaken(f"{host}:{port} is in use")
        self.scene = scene
        rich.reconfigure(quiet=True)  # viser's banners must not mix with `ready` lines on stdout
        answer_other_methods()
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.request_share_url = lambda *args, **kwargs: None  # never tunnel the view off this machine
        self.server.gui.configure_theme(show_share_button=False, control_width="large")
        self.url = f"http://{host}:{self.server.get_port()}"
        self._clouds: dict[str, Any] = {}
        self._bodies: dict[str, Any] = {}
        self._sensors: dict[str, Any] = {}
        self._gizmos: dict[str, Any] = {}
        self._smoke: dict[str, Any] = {}
        self._sliders: dict[str, Any] = {}
        self._dragging: dict[str, bool] = {}
        self._control: ControlClient | None = None
        self.server.on_client_connect(lambda client: on_watchers(len(self.server.get_clients())))
        self.server.on_client_disconnect(lambda client: on_watchers(len(self.server.get_clients())))
        self._draw_static()
        self._time = self.server.gui.add_markdown("**t = 0.000 s**")

    def watchers(self) -> int:
        return len(self.server.get_clients())

    def stop(self) -> None:
        self.server.stop()

    # ------------------------------------------------------------------ drawing

    def _add_shape(self, name: str, shape: Shape, pose: Pose, rgb: tuple[int, int, int], opacity: float | None) -> Any:
        placed = {"wxyz": _wxyz(pose.rotation_deg), "position": pose.position, "color": rgb, "opacity": opacity}
        api = self.server.scene
        if isinstance(shape, Box):
            return api.add_box(name, dimensions=shape.size, **placed)
        if isinstance(shape, Sphere):
            return api.add_icosphere(name, radius=shape.radius, **placed)
        if isinstance(shape, Cylinder):
            return api.add_cylinder(name, radius=shape.radius, height=shape.height, **placed)
        mesh = shape_mesh(shape)
        return api.add_mesh_simple(name, mesh.vertices, mesh.faces, side="double", **placed)

    def _draw_static(self) -> None:
        scene = self.scene
        snapshots = SceneSnapshots(scene)  # keyframed paths need no live state
        self.server.scene.set_up_direction("+z")
        camera = self.server.initial_camera
        camera.position, camera.look_at = INITIAL_CAMERA
        for body in scene.bodies:  # solids and sensors riding on a body hang below its frame
            self._bodies[body.name] = self.server.scene.add_frame(
                f"/bodies/{body.name}", axes_length=0.4, axes_radius=0.02,
                wxyz=_wxyz(body.pose.rotation_deg), position=body.pose.position,
            )
            self._draw_trajectory(body, snapshots)
        for obj in scene.objects:
            rgb = tuple(int(255 * c) for c in material_rgb(scene, obj.material))
            parent = f"/bodies/{obj.body}" if obj.body is not None else "/solids"
            self._add_shape(f"{parent}/{obj.name}", obj.shape, obj.pose, rgb, None)
        smoke_rgb = tuple(int(255 * c) for c in SMOKE_RGB)
        for region in scene.regions:
            self._smoke[region.name] = self._add_shape(f"/smoke/{region.name}", region.shape, region.pose, smoke_rgb, 0.0)
        for spec in scene.sensors:
            self._sensors[spec.name] = self.server.scene.add_frame(
                f"/sensors/{spec.name}", axes_length=0.25, axes_radius=0.012,
                wxyz=_wxyz(spec.pose.rotation_deg), position=spec.pose.position,
            )
            self.server.scene.add_label(f"/sensors/{spec.name}/label", spec.name)

    def _draw_trajectory(self, body: Any, snapshots: SceneSnapshots) -> None:
        """A keyframed body's path over its keyframes, as a line."""
        keyframes = getattr(body.trajectory, "times", None)
        if keyframes is None or len(keyframes) < 2:
            return
        step = max(0.05, float(keyframes[-1] - keyframes[0]) / MAX_TRAJECTORY_POINTS)
        path = snapshots.trajectory(body.name, float(keyframes[0]), float(keyframes[-1]), step)
        segments = np.stack([path[:-1], path[1:]], axis=1).astype(np.float32)
        self.server.scene.add_line_segments(f"/trajectories/{body.name}", segments, colors=TRAJECTORY_RGB, thickness=0.03)

    def build_panel(self, control: ControlClient | None) -> None:
        """The panel's controls, each acting through `control` (None: the daemon has no control API)."""
        gui = self.server.gui
        if control is None:
            gui.add_markdown("Read-only: the daemon's control API is off.")
            return
        self._control = control
        if self.scene.regions:
            with gui.add_folder("Smoke regions (density)"):
                for region in self.scene.regions:
                    top = max(0.01, 2.0 * max(value for _, value in region.density.keyframes))
                    slider = gui.add_slider(region.name, min=0.0, max=round(top, 4), step=0.0001,
                                            initial_value=float(region.density.at(0.0)))
                    slider.on_update(self._acting(lambda event, name=region.name: control.set_density(name, float(event.target.value))))
                    self._sliders[region.name] = slider
        if self.scene.plumes:
            with gui.add_folder("Plumes"):
                for plume in self.scene.plumes:
                    toggle = gui.add_checkbox(f"{plume.name} emitting", initial_value=True)
                    toggle.on_update(self._acting(lambda event, name=plume.name: control.set_emitting(name, bool(event.target.value))))
        for body in self.scene.bodies:
            if isinstance(body.trajectory, Live):
                gizmo = self._gizmos[body.name] = self.server.scene.add_transform_controls(
                    f"/gizmos/{body.name}", scale=GIZMO_SCALE_M, depth_test=False,  # on top: not hidden inside the body's solids
                    position=body.pose.position, wxyz=_wxyz(body.pose.rotation_deg),
                )
                gizmo.on_update(self._acting(lambda event, name=body.name: self._drag(name, event)))
        with gui.add_folder("Clock"):
            speed = gui.add_number("speed", initial_value=1.0, min=0.01, max=100.0, step=0.01)
            speed.on_update(self._acting(lambda event: control.set_clock(speed=float(event.target.value))))
            paused = gui.add_checkbox("paused", initial_value=False)
            paused.on_update(self._acting(lambda event: control.set_clock(paused=bool(event.target.value))))
        self._errors = gui.add_markdown("")

    def _drag(self, body: str, event: Any) -> None:
        """A person drags a live body's gizmo: each pose goes to the control API."""
        target = event.target
        self._dragging[body] = getattr(event, "phase", "update") != "end"
        self._control.set_pose(body, [float(v) for v in target.position], rotation_deg_of(target.wxyz))

    def _acting(self, change: Callable[[Any], None]) -> Callable[[Any], None]:
        """A panel callback: act only on a person's change (not the view's own updates), and
        show the control API's refusal instead of raising in viser's thread."""

        def callback(event: Any) -> None:
            if event.client is None:
                return
            try:
                change(event)
                self._errors.content = ""
            except ControlError as error:
                self._errors.content = f"**refused:** {error}"

        return callback

    # ------------------------------------------------------------------ updates

    def update(self, snapshot: WorldSnapshot, scans: Mapping[str, Scan]) -> None:
        """Draw the world `snapshot` and each sensor's latest scan among `scans`."""
        with self.server.atomic():
            self._time.content = f"**t = {snapshot.time_s:.3f} s**"
            self._draw_poses(snapshot)
            self._draw_smoke(snapshot)
            for name, scan in scans.items():
                self._draw_scan(scan, snapshot.sensor_poses.get(name, Pose()))

    def _draw_poses(self, snapshot: WorldSnapshot) -> None:
        for name, pose in snapshot.body_poses.items():
            handle = self._bodies[name]
            handle.position, handle.wxyz = pose.position, _wxyz(pose.rotation_deg)
            gizmo = self._gizmos.get(name)
            if gizmo is not None and not self._dragging.get(name):
                gizmo.position, gizmo.wxyz = pose.position, _wxyz(pose.rotation_deg)
        for name, pose in snapshot.sensor_poses.items():
            handle = self._sensors.get(name)
            if handle is not None:
                handle.position, handle.wxyz = pose.position, _wxyz(pose.rotation_deg)

    def _draw_smoke(self, snapshot: WorldSnapshot) -> None:
        scene = self.scene
        for region in scene.regions:
            density = snapshot.densities.get(region.name, 0.0)
            alpha = float(smoke_alpha(density, scene.density_to_extinction, thickness_m(region.shape)))
            handle = self._smoke[region.name]
            handle.opacity = alpha
            handle.visible = alpha > 0.0
            slider = self._sliders.get(region.name)
            if slider is not None and abs(slider.value - density) > 5e-5:
                slider.value = round(density, 4)
        for name, particles in snapshot.particles.items():
            edge = float(2.0 * np.mean(particles.half_sizes)) if len(particles) else 0.1
            self._cloud(f"/plumes/{name}", particles.centers.astype(np.float32), np.array([120, 120, 120], np.uint8), edge)

    def _draw_scan(self, scan: Scan, pose: Pose) -> None:
        hits, colours, marks = scan_points(scan, pose)
        self._cloud(f"/scans/{scan.sensor}/echoes", hits, colours, SCAN_POINT_SIZE)
        self._cloud(f"/scans/{scan.sensor}/errors", marks, np.array(ERROR_RGB, np.uint8), SCAN_POINT_SIZE)

    def _cloud(self, name: str, points: np.ndarray, colours: np.ndarray, size: float) -> None:
        """A point cloud, created once and then given new points (cheaper for the browser than a new node)."""
        visible = len(points) > 0
        if not visible:
            points = np.zeros((1, 3), np.float32)  # a hidden node still needs a point
        colours = np.broadcast_to(colours, points.shape).astype(np.uint8)
        handle = self._clouds.get(name)
        if handle is None:
            handle = self._clouds[name] = self.server.scene.add_point_cloud(
                name, points=points, colors=colours, point_size=size, point_shape="circle", precision="float32",
            )
        else:
            handle.points, handle.colors, handle.point_size = points, colours, size
        handle.visible = visible
