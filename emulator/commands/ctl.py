"""`lrf-emulator ctl ...`: change a running daemon from a terminal (docs/control.md).

    ctl state                              the clock, densities, plumes, poses, clients (JSON)
    ctl set region NAME density D          a smoke region holds D from now on
    ctl plume NAME on|off|rate R|wind X Y Z
    ctl pose BODY X Y [Z] [--yaw DEG]      a live body's pose
    ctl twist BODY VX [VY] WZ [--for S]    drive a live body: m/s forward (and left), rad/s turning
    ctl clock [--speed X] [--pause|--resume]
    ctl watch SENSOR [--count N]           a line per scan
"""

from __future__ import annotations

import argparse
import json
import time

from emulator.commands.values import bearer_token, whole_number
from emulator.control.ctl import DEFAULT_URL, ControlClient
from emulator.errors import UserError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _connection_options(parser, DEFAULT_URL, None)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", parser_class=type(parser))
    actions.required = True
    def action(name: str, help_text: str) -> argparse.ArgumentParser:
        action_parser = actions.add_parser(name, help=help_text, description=help_text)
        # after the action too (`ctl watch lidar --url ...`); SUPPRESS keeps one given before it
        _connection_options(action_parser, argparse.SUPPRESS, argparse.SUPPRESS)
        action_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks for errors")
        return action_parser

    action("state", "print the live state as JSON")
    setter = action("set", "set a smoke region's density: set region NAME density D")
    setter.add_argument("what", choices=["region"], help="what to set (a smoke region)")
    setter.add_argument("name", metavar="NAME", help="the region's name in the scene")
    setter.add_argument("key", choices=["density"], help="the quantity to set")
    setter.add_argument("value", type=float, metavar="D", help="the new density (as in the scene file: 0.002 is a light haze)")
    plume = action("plume", "switch a plume on or off, or change its rate or wind: plume NAME on|off|rate R|wind X Y Z")
    plume.add_argument("name", metavar="NAME", help="the plume's name in the scene")
    plume.add_argument("change", choices=["on", "off", "rate", "wind"])
    plume.add_argument("values", nargs="*", type=float, metavar="VALUE", help="R (particles a second) or X Y Z (m/s)")
    pose = action("pose", "move a live body: pose BODY X Y [Z] [--yaw DEG]")
    pose.add_argument("name", metavar="BODY", help="a body with trajectory = \"live\"")
    pose.add_argument("position", nargs="+", type=float, metavar="COORD", help="X Y [Z] in metres, in the scene's frame")
    pose.add_argument("--yaw", type=float, default=0.0, metavar="DEG", help="heading, degrees counter-clockwise (default 0)")
    twist = action("twist", "twist BODY VX [VY] WZ [--for S]: drive a live body (m/s forward and left, rad/s counter-clockwise)")
    twist.add_argument("name", metavar="BODY", help="a body with trajectory = \"live\"")
    twist.add_argument("velocity", nargs="+", type=float, metavar="V",
                       help="VX WZ (a differential drive) or VX VY WZ: m/s forward, m/s to the left, rad/s counter-clockwise")
    twist.add_argument("--for", dest="duration", type=float, default=None, metavar="S",
                       help="keep sending it for S wall seconds (else one command: the body stops after its watchdog)")
    clock = action("clock", "change the simulated clock: clock [--speed X] [--pause|--resume]")
    clock.add_argument("--speed", type=float, default=None, metavar="X", help="simulated seconds per wall second")
    running = clock.add_mutually_exclusive_group()
    running.add_argument("--pause", action="store_true", help="stop simulated time (devices then send nothing new)")
    running.add_argument("--resume", action="store_true", help="let simulated time run again")
    watch = action("watch", "watch SENSOR: a line per scan, until interrupted or --count scans")
    watch.add_argument("sensor", metavar="SENSOR", help="a sensor's name in the scene")
    watch.add_argument("--count", type=whole_number(1), default=None, metavar="N", help="stop after N scans")


def _connection_options(parser: argparse.ArgumentParser, url: str, token: str | None) -> None:
    parser.add_argument("--url", default=url, help=f"the control API (default {DEFAULT_URL})")
    parser.add_argument("--token", type=bearer_token, default=token, help="Bearer token, if serve has --control-token")


def run(args: argparse.Namespace) -> int:
    client = ControlClient(args.url, args.token)
    if args.action == "state":
        print(json.dumps(client.state(), indent=2))
        return 0
    if args.action == "watch":
        client.watch(args.sensor, args.count)
        return 0
    if args.action == "twist":
        return _twist(client, args)
    answer = _change(client, args)
    print(f"applied {json.dumps(answer['applied'])}")
    return 0


def _change(client: ControlClient, args: argparse.Namespace) -> dict:
    if args.action == "set":
        return client.set_region(args.name, args.value)
    if args.action == "plume":
        expected = {"on": 0, "off": 0, "rate": 1, "wind": 3}[args.change]
        if len(args.values) != expected:
            raise UserError(f"plume {args.change}: expected {expected} number(s), got {len(args.values)}")
        if args.change in ("on", "off"):
            return client.plume(args.name, emitting=args.change == "on")
        if args.change == "rate":
            return client.plume(args.name, rate=args.values[0])
        return client.plume(args.name, wind=list(args.values))
    if args.action == "pose":
        if len(args.position) not in (2, 3):
            raise UserError(f"pose: expected X Y [Z], got {len(args.position)} numbers")
        position = [*args.position, 0.0][:3]
        return client.pose(args.name, position, [0.0, 0.0, args.yaw])
    changes: dict = {}
    if args.speed is not None:
        changes["speed"] = args.speed
    if args.pause or args.resume:
        changes["paused"] = bool(args.pause)
    if not changes:
        raise UserError("clock: give --speed X, --pause or --resume")
    return client.clock(**changes)


TWIST_REPEAT_S = 0.05  # `ctl twist --for`: a command every 50 ms, well inside the default 0.5 s watchdog


def _twist(client: ControlClient, args: argparse.Namespace) -> int:
    """One twist command, or (`--for S`) the same one repeated for S wall seconds, as a teleop does."""
    if len(args.velocity) not in (2, 3):
        raise UserError(f"twist: expected VX WZ or VX VY WZ, got {len(args.velocity)} numbers")
    vx, vy, wz = (args.velocity[0], 0.0, args.velocity[1]) if len(args.velocity) == 2 else args.velocity
    if args.duration is not None and not 0 <= args.duration <= 3600:
        raise UserError(f"twist --for: expected 0..3600 seconds, got {args.duration:g}")
    answer = client.twist(args.name, vx, vy, wz)
    print(f"applied {json.dumps(answer['applied'])}")
    if args.duration is not None:
        end = time.monotonic() + args.duration
        while (left := end - time.monotonic()) > 0:
            time.sleep(min(TWIST_REPEAT_S, left))
            answer = client.twist(args.name, vx, vy, wz)
        print(f"last {json.dumps(answer['applied'])}, at {json.dumps(answer['state']['bodies'][args.name])}")
    return 0
