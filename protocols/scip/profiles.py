"""What differs between the SCIP 2.2 Hokuyos served here: identity, range, commands.

One `ScipProfile` per model. The bodies of VV, PP and II follow, field by
field, what the units send (docs/scip.md lists the sources: the SCIP 2.0
specification C-42-03320B, the UTM-30LX-EW / UST protocol documents as quoted by
urg_library, urg_stamped's urg_sim and hokuyolx, and published PP transcripts).
A command a unit does not implement is answered `0E` (undefined command), which
is how drivers (urg_library's `urg_start_measurement`, hence urg_node) learn
that a UTM-30LX has no multi-echo.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.scip.encoding import checksum, encode_values

VENDOR = "Hokuyo Automatic Co., Ltd."
BASE_COMMANDS = frozenset({b"VV", b"PP", b"II", b"BM", b"QT", b"RS", b"RT", b"RB", b"TM", b"SS", b"GD", b"GS", b"MD", b"MS"})
STATE_COMMANDS = frozenset({b"%ST", b"%SL"})  # the UST's state query and sleep (UST protocol, via hokuyolx)
INTENSITY_COMMANDS = frozenset({b"GE", b"ME"})
MULTI_ECHO_COMMANDS = frozenset({b"HD", b"HE", b"ND", b"NE"})
MAX_ECHOES = 3  # SCIP 2.2: up to three echoes per step


@dataclass(frozen=True)
class ScipProfile:
    """One model's SCIP 2.2 identity and abilities.

    `period_ms`: one mirror revolution (SCAN rpm = 60000 / period_ms).
    `interface`: "usb" (unpaced, ptys) or "ethernet" (TCP, `default_port`).
    `ii_style`: "utm" (MESM/STAT words of the UTM family) or "ust".
    """

    model: str  # MODL and PROD
    firmware: str
    default_serial: str
    min_distance_mm: int  # DMIN
    max_distance_mm: int  # DMAX
    steps_per_turn: int  # ARES
    first_step: int  # AMIN
    last_step: int  # AMAX
    front_step: int  # AFRT
    period_ms: int
    interface: str
    ii_style: str
    max_echoes: int = 1

    @property
    def rpm(self) -> int:
        return 60_000 // self.period_ms

    @property
    def max_step(self) -> int:
        """The largest step a request may name: the units accept AMIN..AMAX only."""
        return self.last_step

    @property
    def commands(self) -> frozenset[bytes]:
        extra = (MULTI_ECHO_COMMANDS if self.max_echoes > 1 else frozenset()) | (STATE_COMMANDS if self.ii_style == "ust" else frozenset())
        return BASE_COMMANDS | INTENSITY_COMMANDS | extra

    def version_body(self, serial: str) -> bytes:
        return _lines(("VEND", VENDOR), ("PROD", self.model), ("FIRM", self.firmware), ("PROT", "SCIP 2.2"), ("SERI", serial))

    def parameter_body(self) -> bytes:
        return _lines(
            ("MODL", self.model),
            ("DMIN", str(self.min_distance_mm)),
            ("DMAX", str(self.max_distance_mm)),
            ("ARES", str(self.steps_per_turn)),
            ("AMIN", str(self.first_step)),
            ("AMAX", str(self.last_step)),
            ("AFRT", str(self.front_step)),
            ("SCAN", str(self.rpm)),
        )

    def status_body(self, *, laser_on: bool, streaming: bool, timer_ms: int) -> bytes:
        """II: MODL, LASR, SCSP, MESM, SBPS, TIME (4-character encoded), STAT."""
        if self.ii_style == "utm":
            mesm = "004 Multi_scan" if streaming else "003 Single_scan" if laser_on else "000 Idle"
            stat = "Stable 000 no error."
        else:
            mesm, stat = "Measuring by Sensitive Mode", "sensor is working normally"
        link = "USB Full Speed (12 [Mbps])" if self.interface == "usb" else "Ethernet 100 [Mbps]"
        time_text = encode_values([timer_ms], 4).decode("ascii")
        return _lines(
            ("MODL", self.model),
            ("LASR", "ON" if laser_on else "OFF"),
            ("SCSP", str(self.rpm)),
            ("MESM", mesm),
            ("SBPS", link),
            ("TIME", time_text),
            ("STAT", stat),
        )


def _lines(*fields: tuple[str, str]) -> bytes:
    """`KEY:VALUE;S\\n` per field, S summing the text before the `;`."""
    out = b""
    for key, value in fields:
        text = f"{key}:{value}".encode("ascii")
        out += text + b";" + checksum(text) + b"\n"
    return out


_WIDE = dict(steps_per_turn=1440, first_step=0, last_step=1080, front_step=540, period_ms=25)

PROFILES: dict[str, ScipProfile] = {
    "utm-30lx": ScipProfile(
        "UTM-30LX", "1.1.4 (2009-03-17)", "H0900001", 23, 60000, **_WIDE, interface="usb", ii_style="utm"
    ),
    "utm-30lx-ew": ScipProfile(
        "UTM-30LX-EW", "1.1.0 (2011-09-30)", "H1100001", 23, 60000, **_WIDE, interface="ethernet", ii_style="utm",
        max_echoes=MAX_ECHOES,
    ),
    "ust-10lx": ScipProfile(
        "UST-10LX", "2.23.0000", "H1600001", 20, 30000, **_WIDE, interface="ethernet", ii_style="ust",
        max_echoes=MAX_ECHOES,
    ),
    "ust-20lx": ScipProfile(
        "UST-20LX", "2.23.0000", "H1600002", 20, 60000, **_WIDE, interface="ethernet", ii_style="ust",
        max_echoes=MAX_ECHOES,
    ),
}  # fmt: skip
