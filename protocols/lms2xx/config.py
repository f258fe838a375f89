"""The configuration block read with 74 (F4) and written with 77 (F7), TL §7.46.

34 bytes on firmware V2.30; some older firmware (and the Robotics Library
driver) use a 32-byte block, selected with the "32-byte-config" profile.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.lms2xx.measuring import MEASURING_MODES, MeasuringMode

CONFIG_BYTES_BY_PROFILE = {"v2.30": 34, "32-byte-config": 32}

AVAILABILITY = 4
MEASURING_MODE = 5
UNITS = 6
MULTIPLE_EVALUATION = 9
RESTART = 10
RESTART_TIME = 11

REALTIME_INDICES_BIT = 0x02
UNIT_CODES = {"cm": 0x00, "mm": 0x01}
# 00-06 and 0F; the reserved 0A-0E, 10, 11, 3D, 3E and SICK's internal 3F (energy
# values on a per-unit curve the listing does not give, TL §3.4.2) are refused.
SUPPORTED_MEASURING_MODES = frozenset(MEASURING_MODES)

# The listing's own default: its F4 example telegram (TL Table 7-111, CRC 3C FB)
# carries exactly this block, stop threshold 0x70 included.
_DELIVERY_BLOCK = bytes.fromhex("0000700000000100000202" + "00" * 21 + "0200")


@dataclass(frozen=True)
class Configuration:
    """An immutable configuration block, as long as the firmware profile's."""

    block: bytes

    @classmethod
    def delivery(cls, profile: str, units: str) -> Configuration:
        """The configuration on delivery (TL §10.7) with the given distance unit."""
        if profile not in CONFIG_BYTES_BY_PROFILE:
            raise ValueError(f"unknown firmware profile {profile!r}; choose one of {sorted(CONFIG_BYTES_BY_PROFILE)}")
        if units not in UNIT_CODES:
            raise ValueError(f"units must be 'mm' or 'cm', got {units!r}")
        block = bytearray(_DELIVERY_BLOCK[: CONFIG_BYTES_BY_PROFILE[profile]])
        block[UNITS] = UNIT_CODES[units]
        return cls(bytes(block))

    @property
    def units(self) -> str:
        return "mm" if self.block[UNITS] == UNIT_CODES["mm"] else "cm"

    @property
    def measuring_mode(self) -> MeasuringMode:
        return MEASURING_MODES[self.block[MEASURING_MODE]]

    @property
    def realtime_indices(self) -> bool:
        """Availability bit 1: append scan and telegram indices to measured values."""
        return bool(self.block[AVAILABILITY] & REALTIME_INDICES_BIT)

    def updated(self, data: bytes) -> Configuration | None:
        """This block with its first len(data) bytes replaced, or None when rejected.

        A 77 may be shorter than the block (Player sends 7 bytes): only the
        bytes given change. Bytes beyond the block are ignored, as older
        firmware does (TL §4.4). Rejected: a unit other than cm/mm, or a
        reserved or internal measuring mode.
        """
        block = bytearray(self.block)
        given = data[: len(block)]
        block[: len(given)] = given
        if block[UNITS] not in UNIT_CODES.values() or block[MEASURING_MODE] not in SUPPORTED_MEASURING_MODES:
            return None
        return Configuration(bytes(block))
