"""The LMS200's line-rate model: continuous output sends no more scans than the line carries.

The limit is computed here from first principles: a 180° B0 telegram is
10 + 2·values bytes, 10 bits each; the mirror completes a 1° scan every
revolution (75/s) and a 0.5° scan every two.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from protocols.lms2xx import Lms200Device, build_telegram

SIMULATED_S = 10.0
BAUD_COMMANDS = {9600: b"\x20\x42", 19200: b"\x20\x41", 38400: b"\x20\x40", 500_000: b"\x20\x48"}
VARIANT_COMMANDS = {0.5: bytes.fromhex("3B B4 00 32 00"), 1.0: bytes.fromhex("3B B4 00 64 00")}


def source(time_s: float, *, start_deg: float, step_deg: float, count: int, unit: str, field_bits: int = 13):
    return SimpleNamespace(values=np.full(count, round(time_s * 75) % 8000))


def line_rate_limit(baud: int, resolution_deg: float) -> float:
    values = round(180 / resolution_deg) + 1
    telegram_bytes = 10 + 2 * values  # STX ADDR LEN×2 B0 COUNT×2 values STATUS CRC×2
    mirror_scans_per_s = 75 * resolution_deg
    return min(mirror_scans_per_s, baud / (10 * telegram_bytes))


def stream(baud: int, resolution_deg: float) -> list[tuple[float, bytes]]:
    device = Lms200Device(source)
    device.poll(0.0)
    device.receive(build_telegram(0, BAUD_COMMANDS[baud]), 0.1)
    device.receive(build_telegram(0, VARIANT_COMMANDS[resolution_deg]), 0.2)
    device.receive(build_telegram(0, b"\x20\x24"), 0.3)
    scans = []
    while (deadline := device.next_deadline()) is not None and deadline <= 0.3 + SIMULATED_S:
        scans += [(deadline, output.data) for output in device.poll(deadline) if output.droppable]
    return scans


@pytest.mark.parametrize("resolution_deg", [0.5, 1.0])
@pytest.mark.parametrize("baud", [9600, 19200, 38400, 500_000])
def test_scans_per_second_follow_the_line_rate(baud: int, resolution_deg: float) -> None:
    scans = stream(baud, resolution_deg)
    times = [time for time, _ in scans]
    measured = (len(times) - 1) / (times[-1] - times[0])
    assert measured == pytest.approx(line_rate_limit(baud, resolution_deg), rel=0.10)
    assert all(b - a >= len(data) * 10 / baud - 1e-9 for (a, data), (b, _) in zip(scans, scans[1:]))


@pytest.mark.parametrize("resolution_deg", [0.5, 1.0])
def test_500k_carries_every_scan(resolution_deg: float) -> None:
    scans = stream(500_000, resolution_deg)
    revolutions = [int(np.frombuffer(data[7:9], dtype="<u2")[0]) for _, data in scans]
    step = round(1 / resolution_deg)
    assert np.all(np.diff(revolutions) == step)  # no scan skipped


@pytest.mark.parametrize("resolution_deg", [0.5, 1.0])
@pytest.mark.parametrize("baud", [9600, 38400, 500_000])
def test_next_scan_time_names_the_scan_the_next_telegram_carries(baud: int, resolution_deg: float) -> None:
    """A daemon computes that scan ahead: on a slow line it is the newest scan complete
    when the line frees, not the line-free time the deadline gives."""
    asked: list[float] = []

    def recording(time_s: float, **request):
        asked.append(time_s)
        return source(time_s, **request)

    device = Lms200Device(recording)
    device.poll(0.0)
    device.receive(build_telegram(0, BAUD_COMMANDS[baud]), 0.1)
    device.receive(build_telegram(0, VARIANT_COMMANDS[resolution_deg]), 0.2)
    device.receive(build_telegram(0, b"\x20\x24"), 0.3)
    foreseen, missed = [], 0
    while (deadline := device.next_deadline()) is not None and deadline <= 0.3 + SIMULATED_S:
        foreseen.append(device.next_scan_time())
        asked.clear()
        device.poll(deadline)
        missed += asked != [foreseen[-1]]
    assert len(foreseen) > 10 and missed == 0, (missed, len(foreseen))
