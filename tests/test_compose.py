"""compose.yaml: railway as a fleet, one service per sensor group, sharing one epoch.

Docker cannot run here, so the checks are what the file promises: every
service runs the Dockerfile's image with a command the CLI accepts, the groups
cover the scene's sensors once each, all share the epoch variable, and each
endpoint's port is published on the host's loopback.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from emulator.cli import build_parser
from emulator.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
EPOCH_VARIABLE = re.compile(r"^\$\{LRF_EPOCH:\?[^}]*\}$")


def services() -> dict:
    return yaml.safe_load((ROOT / "compose.yaml").read_text())["services"]


def test_each_service_serves_a_group_of_railway_with_the_shared_epoch() -> None:
    served: list[str] = []
    for name, service in services().items():
        assert service["build"] == "." and service["image"] == "lrf-emulator", name
        command = list(service["command"])
        epoch = command.index("--epoch") + 1
        assert EPOCH_VARIABLE.match(command[epoch]), command[epoch]
        command[epoch] = "1700000000"
        args = build_parser().parse_args(command)
        assert args.command == "serve" and args.scene == "railway" and args.epoch == 1700000000.0
        group = args.sensors.split(",")
        served += group
        published = {int(port.rsplit(":", 2)[-1]) for port in service["ports"]}
        assert all(port.startswith("127.0.0.1:") for port in service["ports"])
        for endpoint in args.endpoint:
            sensor, uri = endpoint.split("=", 1)
            assert sensor in group
            host, port = uri.removeprefix("tcp:").rsplit(":", 1)
            assert host == "0.0.0.0" and int(port) in published
    assert sorted(served) == sorted(spec.name for spec in load_scene("railway").sensors)
