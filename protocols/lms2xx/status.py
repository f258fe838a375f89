"""The 152-byte status block of reply B1 (TL §7.6.2), with the live fields drivers read.

Offsets below are 1-based data-byte indices, as sicktoolbox reads them (index
0 is the B1 code). Fields the emulator has no model for stay zero, which the
drivers we know accept.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.lms2xx.config import MEASURING_MODE, MULTIPLE_EVALUATION, RESTART, RESTART_TIME, Configuration

STATUS_BLOCK_BYTES = 152
BAUD_CODES = {9600: 0x8067, 19200: 0x8033, 38400: 0x8019, 500_000: 0x8001}
# "microseconds for 1/90 of a revolution" at 75 revolutions per second.
_MOTOR_WORD = round(1e6 / 75 / 90)


@dataclass(frozen=True)
class DeviceStatus:
    """What B1 reports about the device right now."""

    software_version: str  # 7 ASCII characters, e.g. "V02.10 "
    operating_mode: int
    angle_deg: int
    resolution_cdeg: int
    baud: int
    permanent_baud: bool
    configuration: Configuration


def _put_word(block: bytearray, index: int, value: int) -> None:
    block[index - 1 : index + 1] = value.to_bytes(2, "little")


def status_block(status: DeviceStatus) -> bytes:
    """The B1 data bytes (without the B1 code and the status byte)."""
    block = bytearray(STATUS_BLOCK_BYTES)
    version = status.software_version.encode("ascii")[:7].ljust(7, b" ")
    config = status.configuration.block
    block[0:7] = version  # 1–7 system software version
    block[7] = status.operating_mode  # 8
    block[8] = 0  # 9 status: no error
    block[17] = 0  # 18 variant type: standard LMS2xx, type 6
    _put_word(block, 67, _MOTOR_WORD)  # 67–68 motor revolutions
    block[101] = config[MEASURING_MODE]  # 102 measuring mode
    _put_word(block, 107, status.angle_deg)  # 107–108 scanning angle
    _put_word(block, 109, status.resolution_cdeg)  # 109–110 resolution in 1/100°
    block[110] = config[RESTART]  # 111 restart mode
    _put_word(block, 112, config[RESTART_TIME])  # 112–113 restart time
    _put_word(block, 116, BAUD_CODES[status.baud])  # 116–117 active baud rate
    block[117] = config[MULTIPLE_EVALUATION]  # 118 evaluation number
    block[118] = 1 if status.permanent_baud else 0  # 119 permanent baud rate
    block[119] = 0  # 120 LMS address
    block[121] = 1 if status.configuration.units == "mm" else 0  # 122 unit
    block[122] = 1  # 123 laser on
    block[123:130] = version  # 124–130 boot PROM version
    return bytes(block)
