"""The URG-04LX's identity: VV, PP and II bodies, byte-exact to a real unit
(firmware 3.1.04, tests/protocols/data/urg04lx-real-session.txt).

Each body line is `KEY:VALUE;S` where S sums only the text before the `;`.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.scip.encoding import checksum

MODEL = "URG-04LX(Hokuyo Automatic Co.,Ltd.)"
VENDOR = "Hokuyo Automatic Co.,Ltd."
PRODUCT = "SOKUIKI Sensor URG-04LX"
FIRMWARE = "3.1.04(02/Aug./2007)"
DEFAULT_SERIAL = "H0706400"

MIN_DISTANCE_MM = 20
MAX_DISTANCE_MM = 5600
STEPS_PER_TURN = 1024
FIRST_STEP = 44  # AMIN: first step of the measurement range
LAST_STEP = 725  # AMAX
FRONT_STEP = 384
MAX_STEP = 768  # GD/MD accept steps 0..768 (spec p.4, p.10); outside AMIN..AMAX they carry error codes
DEFAULT_RPM = 600
DEFAULT_BIT_RATE = 19200
RPM_PER_SPEED_LEVEL = 6  # CR01..CR10 slow the motor by 6 rpm a level (600 → 540)


def info_line(key: str, value: str) -> bytes:
    """`KEY:VALUE;S\\n`."""
    text = f"{key}:{value}".encode("ascii")
    return text + b";" + checksum(text) + b"\n"


def version_body(serial: str) -> bytes:
    """The VV lines."""
    return b"".join(
        (
            info_line("VEND", VENDOR),
            info_line("PROD", PRODUCT),
            info_line("FIRM", FIRMWARE),
            info_line("PROT", "SCIP 2.0"),
            info_line("SERI", serial),
        )
    )


def parameter_body() -> bytes:
    """The PP lines."""
    return b"".join(
        (
            info_line("MODL", MODEL),
            info_line("DMIN", str(MIN_DISTANCE_MM)),
            info_line("DMAX", str(MAX_DISTANCE_MM)),
            info_line("ARES", str(STEPS_PER_TURN)),
            info_line("AMIN", str(FIRST_STEP)),
            info_line("AMAX", str(LAST_STEP)),
            info_line("AFRT", str(FRONT_STEP)),
            info_line("SCAN", str(DEFAULT_RPM)),
        )
    )


@dataclass(frozen=True)
class LiveState:
    """What II reports: live device state."""

    laser_on: bool
    speed_level: int  # 0 = default, 1..10 = CR levels
    bit_rate: int
    timer_ms: int  # the 24-bit device timer


def status_body(state: LiveState) -> bytes:
    """The II lines: exactly 7, as hokuyo_node and urg_library expect.

    MESM is CLASSIC while the laser is on (real capture) and IDLE while it is
    off (Hokuyo's urgnetwork wiki). Non-default speed and bit rate have no
    capture; SCSP keeps a 7-letter word before `(` so parsers written for
    `Initial(600[rpm])` still read the rpm.
    """
    if state.speed_level == 0:
        speed = f"Initial({DEFAULT_RPM}[rpm])<-Default setting by user"
    else:
        speed = f"Changed({DEFAULT_RPM - RPM_PER_SPEED_LEVEL * state.speed_level}[rpm])"
    if state.bit_rate == DEFAULT_BIT_RATE:
        bit_rate = f"{DEFAULT_BIT_RATE}[bps]<-Default setting by user"
    else:
        bit_rate = f"{state.bit_rate}[bps]"
    return b"".join(
        (
            info_line("MODL", MODEL),
            info_line("LASR", "ON" if state.laser_on else "OFF"),
            info_line("SCSP", speed),
            info_line("MESM", "CLASSIC" if state.laser_on else "IDLE"),
            info_line("SBPS", bit_rate),
            info_line("TIME", f"{state.timer_ms:06X}"),
            info_line("STAT", "Sensor works well."),
        )
    )
