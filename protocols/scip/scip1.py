"""SCIP 1.1, the protocol many URG-04LX units boot in (an option here).

Formats from the SCIP 1 notes and parser of GearBox's urg_nz driver
(naderman/gearbox, submitted/urg_nz/urg_nz.cpp, Geoffrey Biggs, AIST):
- no checksums anywhere; a one-character status, `0` = OK;
- `V` → `V\\n0\\n` VEND/PROD/FIRM/PROT/SERI lines, empty line. A 3.x firmware's
  FIRM line carries the ranges, e.g. that driver's own example for firmware
  3.1.04: `FIRM:3.1.04,07/08/02(20-4095[mm],240[deg],44-725[step],600[rpm])`;
- `GsssEEEcc` (start, end: 3 digits; cluster: 2) → echo, `0`, the latest
  scan's values 2-character encoded in 64-character lines, empty line;
  no timestamp.
`SCIP2.0` → `SCIP2.0\\n0\\n\\n` (fact sheet). Anything else, including a
malformed `G`, gets echo + `E` + empty line: no public source gives 1.1's
per-field error codes, and every client only tests for `0`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from protocols.scip.encoding import cluster_minimum, data_lines, encode_values
from protocols.scip.identity import MAX_STEP, PRODUCT, VENDOR

SWITCH_COMMAND = b"SCIP2.0"
SWITCH_REPLY = b"SCIP2.0\n0\n\n"
FIRMWARE = "3.1.04,07/08/02(20-4095[mm],240[deg],44-725[step],600[rpm])"
VALUE_CHARS = 2


def reply(line: bytes, latest_values: Callable[[], np.ndarray], serial: str) -> bytes:
    """The SCIP 1.1 reply to one command line (not `SCIP2.0`, which the device handles)."""
    if line == b"V":
        return _version(serial)
    if line[:1] == b"G":
        return _distances(line, latest_values)
    return refusal(line)


def refusal(line: bytes) -> bytes:
    """Echo + `E`: the command is unknown or malformed."""
    return line + b"\nE\n\n"


def _version(serial: str) -> bytes:
    lines = (
        f"VEND:{VENDOR}",
        f"PROD:{PRODUCT}",
        f"FIRM:{FIRMWARE}",
        "PROT:SCIP 1.1",
        f"SERI:{serial}",
    )
    return b"V\n0\n" + "".join(f"{text}\n" for text in lines).encode("ascii") + b"\n"


def _distances(line: bytes, latest_values: Callable[[], np.ndarray]) -> bytes:
    params = line[1:]
    if len(params) != 8 or not params.isdigit():
        return refusal(line)
    start, end, cluster = int(params[0:3]), int(params[3:6]), max(int(params[6:8]), 1)
    if end > MAX_STEP or end < start:
        return refusal(line)
    values = cluster_minimum(latest_values()[start : end + 1], cluster)
    return line + b"\n0\n" + data_lines(encode_values(values, VALUE_CHARS), with_checksums=False) + b"\n"
