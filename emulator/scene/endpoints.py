"""Endpoint URIs of the scene format (`pty:PATH`, `tcp:HOST:PORT`, `rfc2217:HOST:PORT`) and the clash rule.

They are scene data: the loader validates them, `serve --endpoint` parses the
same syntax, and the transports bind what they describe.
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass
from typing import Mapping, Sequence, Union

from emulator.errors import UserError
from emulator.scene.model import Scene, SensorSpec

WILDCARD = "*"  # a bind to 0.0.0.0 or :: owns its port on every address (Linux)
HOST_ALIASES = {"localhost": "127.0.0.1"}


@dataclass(frozen=True)
class PtyAddress:
    """`pty:PATH`: a pty published under the symlink PATH (relative to the cwd)."""

    path: str

    def __str__(self) -> str:
        return f"pty:{self.path}"


@dataclass(frozen=True)
class TcpAddress:
    """`tcp:HOST:PORT`; port 0 lets the system choose (the ready line names it)."""

    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp:{host}:{self.port}"


@dataclass(frozen=True)
class Rfc2217Address(TcpAddress):
    """`rfc2217:HOST:PORT`: a TCP port speaking RFC 2217 (serial over telnet, with
    line control), so a client sets the baud over the network as on a serial port.
    It takes a TCP port like `tcp:`, so the two clash on one port."""

    def __str__(self) -> str:
        return "rfc2217:" + super().__str__().removeprefix("tcp:")


Address = Union[PtyAddress, TcpAddress, Rfc2217Address]
EXPECTED = "pty:PATH, tcp:HOST:PORT or rfc2217:HOST:PORT with PORT 0..65535"


def parse_endpoint(uri: str) -> Address:
    """`pty:PATH`, `tcp:HOST:PORT` or `rfc2217:HOST:PORT` (IPv6 hosts in brackets;
    port 0: the system chooses, in a scene file as on `--endpoint`); UserError otherwise."""
    scheme, sep, rest = uri.partition(":")
    if sep and scheme == "pty":
        if not rest:
            raise UserError(f"endpoint {uri!r}: pty needs a path (pty:PATH)")
        if "\0" in rest:
            raise UserError(f"endpoint {uri!r}: a path cannot hold a NUL byte")
        return PtyAddress(rest)
    if sep and scheme in ("tcp", "rfc2217"):
        host, sep, port_text = rest.rpartition(":")
        bracketed = host.startswith("[") and host.endswith("]")
        host = host[1:-1] if bracketed else host
        if not sep or not host or not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise UserError(f"endpoint {uri!r}: expected {scheme}:HOST:PORT with PORT 0..65535")
        if ":" in host and not bracketed and not _is_ipv6(host):  # tcp:::0 read as host ":"
            raise UserError(f"endpoint {uri!r}: an IPv6 host goes in brackets ({scheme}:[::]:PORT, {scheme}:[::1]:PORT)")
        kind = TcpAddress if scheme == "tcp" else Rfc2217Address
        return kind(host, int(port_text))
    raise UserError(f"endpoint {uri!r}: expected {EXPECTED}")


def _is_ipv6(host: str) -> bool:
    try:
        ipaddress.IPv6Address(host)
    except ValueError:
        return False
    return True


def endpoints_clash(first: Address, second: Address) -> bool:
    """Whether `second` could not be served beside `first`: the same pty path, or one
    TCP port on the same host or with a wildcard host on either side. Port 0 asks
    for a fresh port each time, so it never clashes."""
    if isinstance(first, PtyAddress) and isinstance(second, PtyAddress):
        return os.path.abspath(first.path) == os.path.abspath(second.path)
    if isinstance(first, TcpAddress) and isinstance(second, TcpAddress):
        if first.port != second.port or first.port == 0:
            return False
        hosts = {_bind_host(first.host), _bind_host(second.host)}
        return len(hosts) == 1 or WILDCARD in hosts
    return False


def _bind_host(host: str) -> str:
    """One spelling per host as bind() sees it: case-insensitive, `localhost` as
    127.0.0.1, IP addresses in canonical form, every wildcard as WILDCARD."""
    host = HOST_ALIASES.get(host.lower(), host.lower())
    if host == WILDCARD:
        return WILDCARD
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host
    return WILDCARD if address.is_unspecified else str(address)


class EndpointClaims:
    """The endpoints taken so far and by whom, to refuse one that would clash when bound."""

    def __init__(self) -> None:
        self._taken: list[tuple[Address, str]] = []

    def claim(self, address: Address, owner: str) -> tuple[Address, str] | None:
        """Take `address` for `owner`; if it clashes, the (endpoint, owner) already there instead."""
        clash = next(((taken, holder) for taken, holder in self._taken if endpoints_clash(taken, address)), None)
        if clash is None:
            self._taken.append((address, owner))
        return clash


def plan_endpoints(
    scene: Scene, overrides: Mapping[str, Sequence[str]] | None = None
) -> list[tuple[SensorSpec, tuple[Address, ...]]]:
    """Each sensor with the endpoints it is served on. The scene's own never clash (the
    loader refuses it), but `--endpoint` can name an unknown sensor, a bad URI, or bring
    one onto a port or path another endpoint keeps: a UserError before anything is served."""
    overrides = dict(overrides or {})
    known = {spec.name for spec in scene.sensors}
    for name in overrides:
        if name not in known:
            raise UserError(f"--endpoint: no sensor named {name!r} (known: {', '.join(sorted(known)) or 'none'})")
    plan = []
    claims = EndpointClaims()
    for spec in scene.sensors:
        addresses = tuple(parse_endpoint(uri) for uri in overrides.get(spec.name, spec.endpoints))
        for address in addresses:
            clash = claims.claim(address, spec.name)
            if clash is not None:
                taken, owner = clash
                spelled = "" if taken == address else f" as {taken}"
                raise UserError(
                    f"--endpoint: endpoint {address} of sensor {spec.name!r} already used by sensor {owner!r}{spelled}"
                )
        if addresses:
            plan.append((spec, addresses))
    return plan
