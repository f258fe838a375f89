"""Parsing GD/GS/MD/MS parameters into a `ScanRequest` or the device's status.

Statuses (spec p.11, p.13): 01 start, 02 end, 03 cluster, 06 interval,
07 count not numeric; 04 end beyond the last step (768); 05 end < start.
A start beyond 768 is caught by 04 or 05, as on the real unit.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocols.scip.identity import MAX_STEP

SCAN_PARAMETER_CHARS = 10  # ssss eeee cc
STREAM_PARAMETER_CHARS = 13  # ssss eeee cc i nn


@dataclass(frozen=True)
class ScanRequest:
    """Which steps, how clustered, and for MD/MS how often and how many times."""

    start: int
    end: int
    cluster: int  # 1..99 (00 and 01 both mean 1)
    interval: int = 0  # rotations skipped between streamed scans
    count: int = 1  # 0 = unlimited


def parse_scan_request(params: bytes, *, streaming: bool, max_step: int = MAX_STEP) -> ScanRequest | bytes:
    """The request in `params` (exact length already checked), or a status; `max_step` is the
    last step the unit accepts (URG-04LX 768, SCIP 2.2 units their AMAX)."""
    fields = [(params[0:4], b"01"), (params[4:8], b"02"), (params[8:10], b"03")]
    if streaming:
        fields += [(params[10:11], b"06"), (params[11:13], b"07")]
    for digits, status in fields:
        if not digits.isdigit():
            return status
    start, end, cluster = int(params[0:4]), int(params[4:8]), int(params[8:10])
    if end > max_step:
        return b"04"
    if end < start:
        return b"05"
    if not streaming:
        return ScanRequest(start=start, end=end, cluster=max(cluster, 1))
    return ScanRequest(
        start=start, end=end, cluster=max(cluster, 1), interval=int(params[10:11]), count=int(params[11:13])
    )
