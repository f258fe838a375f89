"""docs/ros.md's cmd_vel bridge, run as printed against the real daemon serving rescue-live.

rclpy cannot run here (no ROS), so the node's three calls (init, create_node with
create_subscription, spin) and geometry_msgs' Twist are stand-ins; the bridge's own
code (the HTTP request to the twist endpoint, its error handling) runs unchanged,
only the control API's address is the test daemon's.
"""

from __future__ import annotations

import json
import re
import sys
import time
import types
import urllib.request
from pathlib import Path

from emulator.bench.serve_process import ServeProcess

ROOT = Path(__file__).resolve().parents[2]


def bridge_source() -> str:
    """The Python block of docs/ros.md's "Driving the robot from `cmd_vel`" section."""
    text = (ROOT / "docs" / "ros.md").read_text()
    section = text[text.index("## Driving the robot from `cmd_vel`"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


class StandInNode:
    def __init__(self) -> None:
        self.callbacks, self.warnings = {}, []

    def create_subscription(self, message_type, topic, callback, depth):
        self.callbacks[topic] = callback

    def get_logger(self):
        return types.SimpleNamespace(warning=self.warnings.append)


def load_bridge(control_url: str, node: StandInNode) -> dict:
    """Execute the bridge with stand-in rclpy and geometry_msgs modules; return its namespace."""
    rclpy = types.ModuleType("rclpy")
    rclpy.init = lambda: None
    rclpy.create_node = lambda name: node
    rclpy.spin = lambda spun: None
    geometry = types.ModuleType("geometry_msgs")
    geometry.msg = types.ModuleType("geometry_msgs.msg")
    geometry.msg.Twist = object
    saved = {name: sys.modules.get(name) for name in ("rclpy", "geometry_msgs", "geometry_msgs.msg")}
    sys.modules.update({"rclpy": rclpy, "geometry_msgs": geometry, "geometry_msgs.msg": geometry.msg})
    argv, sys.argv = sys.argv, ["cmd_vel_bridge", "robot"]
    try:
        namespace: dict = {"__name__": "__main__"}
        exec(compile(bridge_source().replace("http://127.0.0.1:8765", control_url), "cmd_vel_bridge", "exec"), namespace)
        return namespace
    finally:
        sys.argv = argv
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module


def twist(vx: float, wz: float) -> types.SimpleNamespace:
    vector = types.SimpleNamespace
    return types.SimpleNamespace(linear=vector(x=vx, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=wz))


def robot_state(control_url: str) -> dict:
    with urllib.request.urlopen(control_url + "/api/state", timeout=10) as answer:
        return json.load(answer)["bodies"]["robot"]


def test_cmd_vel_drives_rescue_lives_robot_and_a_refused_twist_is_logged(tmp_path: Path) -> None:
    with ServeProcess("rescue-live", ["urg=tcp:127.0.0.1:0", f"lms=pty:{tmp_path / 'lms'}"]) as daemon:
        node = StandInNode()
        load_bridge(daemon.control_url.rstrip("/"), node)
        forward = node.callbacks["cmd_vel"]
        start = robot_state(daemon.control_url.rstrip("/"))
        for _ in range(5):  # a navigation stack sends cmd_vel at 10 Hz or more: inside the 0.5 s watchdog
            forward(twist(0.3, 0.0))
            time.sleep(0.1)
        moving = robot_state(daemon.control_url.rstrip("/"))
        assert moving["twist"] == {"vx": 0.3, "vy": 0.0, "wz": 0.0}
        assert moving["position"] != start["position"]
        forward(twist(1.5, 0.0))  # over rescue-live's max_speed (1 m/s): the daemon refuses, the bridge logs it
        assert len(node.warnings) == 1 and "max_speed" in node.warnings[0]
