"""RFC 2217: a serial port over TCP (telnet with the COM-PORT-OPTION), as
serial-port servers (ser2net, Moxa NPort) offer and pyserial's `rfc2217://`
URLs speak. The client sets the baud over the network; the endpoint keeps it
as a pty keeps the client's termios speed, and drops received bytes while it
differs from the device's rate (a wrong-rate line garbles). Output is paced
at the device's rate as on any endpoint.

The telnet and COM-PORT-OPTION negotiation is pyserial's own `PortManager`,
given a small object with the line settings it reads and writes. Data without
an IAC byte (0xFF) passes straight through; only input holding one goes
through the manager's byte filter. Outgoing IAC bytes are doubled once per
output (bytes.replace), so pacing counts the doubled byte too: a 0xFF costs one
extra byte time on the line (< 0.5 % of an LMS200 telegram on average).
"""

from __future__ import annotations

import dataclasses
import socket
from dataclasses import dataclass

from serial.rfc2217 import IAC, M_NORMAL, PortManager

from emulator.scene.endpoints import Rfc2217Address
from emulator.transport import Session
from emulator.transport.link import READ_SIZE, unsent_bytes
from emulator.transport.outbox import DEFAULT_LIMIT_BYTES
from emulator.transport.tcp import IDLE_TIMEOUT_S, TcpEndpoint
from protocols.device import Output

DEFAULT_BAUD = 9600  # what a client that asks before setting one is told, for an unpaced device
MAX_SUBOPTION_BYTES = 64  # the longest COM-PORT-OPTION is 6; a longer one is hostile and dropped


@dataclass
class LineSettings:
    """The serial port `PortManager` configures: what the client set, and modem lines
    that say a device is there (CTS, DSR, CD up)."""

    baudrate: int = DEFAULT_BAUD
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1
    xonxoff: bool = False
    rtscts: bool = False
    dtr: bool = True
    rts: bool = True
    break_condition: bool = False
    cts: bool = True
    dsr: bool = True
    ri: bool = False
    cd: bool = True

    def reset_input_buffer(self) -> None:
        """Nothing is buffered on our side of the line."""

    def reset_output_buffer(self) -> None:
        """The device's output is paced by the outbox; a purge leaves it (the device decides)."""


class Rfc2217Endpoint(TcpEndpoint):
    """Serves one session on a TCP port speaking RFC 2217."""

    def __init__(
        self, address: Rfc2217Address, session: Session, *, limit_bytes: int = DEFAULT_LIMIT_BYTES,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
    ) -> None:
        super().__init__(address, session, limit_bytes=limit_bytes, idle_timeout_s=idle_timeout_s)
        self.line: LineSettings | None = None
        self._manager: PortManager | None = None

    def send(self, outputs: list[Output]) -> None:
        """Device output, its IAC bytes doubled for telnet."""
        super().send([_escaped(output) for output in outputs])

    def write(self, data: bytes) -> None:
        """PortManager's connection: negotiation replies, unpaced, in order with the data."""
        super().send([Output(data)])

    def _attach(self, client: socket.socket) -> None:
        self.line = LineSettings(baudrate=self._session.baud or DEFAULT_BAUD)
        self._connect(
            self._loop,
            client.fileno(),
            read=lambda: self._data_from(client.recv(READ_SIZE)),
            write=client.send,
            kernel_backlog=lambda: unsent_bytes(client.fileno()),
            on_lost=self._client_left,
            accepts_input=self._at_device_rate,
        )
        self._manager = PortManager(self.line, self)  # asks the client for BINARY, SGA, COM-PORT-OPTION

    def _data_from(self, received: bytes) -> bytes:
        """The serial data in what the client sent; telnet commands go to the manager.
        Raises BlockingIOError when there was nothing but telnet (b"" means end of stream)."""
        manager = self._manager
        if not received or manager is None:
            return received
        if IAC not in received and manager.mode == M_NORMAL and manager.suboption is None:
            return received
        data = b"".join(manager.filter(received))
        if manager.suboption is not None and len(manager.suboption) > MAX_SUBOPTION_BYTES:
            manager.suboption, manager.mode = None, M_NORMAL  # never buffer an endless subnegotiation
        if not data:
            raise BlockingIOError
        return data

    def _at_device_rate(self) -> bool:
        baud = self._session.baud
        return baud is None or self.line is None or self.line.baudrate == baud

    def _drop_client(self) -> None:
        super()._drop_client()
        self._manager = None


def _escaped(output: Output) -> Output:
    if IAC not in output.data:
        return output
    return dataclasses.replace(output, data=output.data.replace(IAC, IAC + IAC))
