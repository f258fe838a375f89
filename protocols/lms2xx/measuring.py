"""Measuring modes of the configuration block (77 byte 5, TL Table 7-122 block D):
how many bits a value's distance takes and what its upper bits carry.

| mode | distance bits (range in mm / cm) | upper bits |
|---|---|---|
| 00 | 0–12 (8 m / 80 m) | 13 field A, 14 field B, 15 dazzle |
| 01 | 0–12 (8 m / 80 m) | 13–15 reflector, 8 levels |
| 02 | 0–12 (8 m / 80 m) | 13 field A, 14 field B, 15 field C |
| 03 | 0–13 (16 m) | 14–15 reflector, 4 levels |
| 04 | 0–13 (16 m) | 14 field A, 15 field B |
| 05 | 0–14 (32 m) | 15 reflector, 2 levels |
| 06 | 0–14 (32 m) | 15 field A |
| 0F | 0–14 (32 m) | none (immediate data transmission) |

The listing prints mode 05 as "bit 0 to bit 13 / bit 14 to bit 15" but
calls it 32 m with "2 levels (2^1)" of reflector values: 32 m needs 15 bits
(TL Table 3-7, 7FF7h) and 2 levels one bit, as mode 06 shows; we follow that.
The error codes (8183 above maximum … 8191 no echo) sit at the top of the
distance field: 3FF7h… in a 14-bit field, 7FF7h… in a 15-bit one (Table 3-7's
"max. representation"). No fields are defined in the emulator, so field bits
are 0; dazzle is 0. A reflector is sent at the top level (the sensor says
per beam whether its echo came from a retro-reflector; this module only encodes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MeasuringMode:
    code: int
    field_bits: int  # bits 0..field_bits-1 carry the distance or an error code
    reflector_bits: int = 0  # how many bits above the distance carry the reflector level

    def encode(self, values: np.ndarray, reflector: np.ndarray | None) -> np.ndarray:
        """Wire words: distances/codes in the field, the reflector level above it."""
        words = np.asarray(values, dtype=np.int64) & ((1 << self.field_bits) - 1)
        if self.reflector_bits and reflector is not None:
            top_level = (1 << self.reflector_bits) - 1
            words = words | (np.asarray(reflector, dtype=bool).astype(np.int64) * top_level) << self.field_bits
        return words


MEASURING_MODES = {
    mode.code: mode
    for mode in (
        MeasuringMode(0x00, 13),
        MeasuringMode(0x01, 13, reflector_bits=3),
        MeasuringMode(0x02, 13),
        MeasuringMode(0x03, 14, reflector_bits=2),
        MeasuringMode(0x04, 14),
        MeasuringMode(0x05, 15, reflector_bits=1),
        MeasuringMode(0x06, 15),
        MeasuringMode(0x0F, 15),
    )
}
