"""LMS200 scans per second delivered through the real daemon, against the line-rate limit.

A real LMS200 measures 75 revolutions/s, but its serial line cannot carry a
telegram per revolution below 500 kBd, so it skips scans (docs/lms200.md).
This starts `lrf-emulator serve` with the LMS on a pty, drives it like a
driver (baud switch with 20 4x following the port's termios, resolution with
3B, continuous mode 20 24), counts complete CRC-valid B0 telegrams and
compares their rate with min(mirror rate, baud / (10 × telegram bytes)).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from emulator.bench.lms_client import BAUD_COMMANDS, LmsSerialClient, Telegram
from emulator.bench.serve_process import ServeProcess, private_endpoints

MIRROR_HZ = 75.0
BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit
FIELD_OF_VIEW_DEG = 180


def values_per_scan(resolution_deg: float, angle_deg: int = FIELD_OF_VIEW_DEG) -> int:
    return int(round(angle_deg / resolution_deg)) + 1


def b0_telegram_bytes(resolution_deg: float) -> int:
    """STX ADDR LEN(2) B0 count(2) values(2 each) STATUS CRC(2): 732 at 0.5°, 372 at 1°."""
    return 4 + 1 + 2 + 2 * values_per_scan(resolution_deg) + 1 + 2


def line_rate_limit(baud: int, resolution_deg: float) -> float:
    """Scans/s the line can carry, capped by the mirror (one scan per 1/res revolutions)."""
    mirror_limit = MIRROR_HZ * resolution_deg  # 75/s at 1°, 37.5/s at 0.5°
    return min(mirror_limit, baud / (BITS_PER_BYTE * b0_telegram_bytes(resolution_deg)))


def count_streamed_scans(client: LmsSerialClient, expected_values: int, duration_s: float) -> list[Telegram]:
    """The full B0 scans (CRC-valid, `expected_values` values) arriving within `duration_s`."""
    return [
        event for event in client.events(duration_s)
        if isinstance(event, Telegram) and event.command == 0xB0
        and event.b0_values()[0] & 0x3FF == expected_values
    ]


def measure_stream(client: LmsSerialClient, baud: int, resolution_deg: float, duration_s: float) -> dict:
    """Switch the device (and the port) to `baud` and `resolution_deg`, stream, count.

    Streams for `duration_s`, or longer where the line carries fewer than 4
    telegrams in that time (9600 Bd, 0.5°: 1.3/s), so every cell has a rate.
    """
    if client.baud != baud:
        client.switch_baud(baud)
    resolution = int(round(resolution_deg * 100))
    _, switched = client.request(bytes([0x3B, FIELD_OF_VIEW_DEG, 0, resolution, 0]))
    if switched.data[:1] != b"\x01":
        raise RuntimeError(f"3B {FIELD_OF_VIEW_DEG}°/{resolution_deg}° refused: {switched.raw.hex(' ')}")
    client.request(b"\x20\x24")
    limit = line_rate_limit(baud, resolution_deg)
    scans = count_streamed_scans(client, values_per_scan(resolution_deg), max(duration_s, 4.5 / limit))
    client.request(b"\x20\x25")
    client.discard_input()
    span = scans[-1].arrived - scans[0].arrived if len(scans) >= 2 else 0.0
    measured = (len(scans) - 1) / span if span > 0 else 0.0
    deviation_ms = period_deviation_ms([scan.arrived for scan in scans])
    return {
        "baud": baud,
        "resolution_deg": resolution_deg,
        "telegram_bytes": b0_telegram_bytes(resolution_deg),
        "scans": len(scans),
        "measured_per_s": measured,
        "limit_per_s": limit,
        "ratio": measured / limit,
        "period_deviation_p50_ms": deviation_ms[0],
        "period_deviation_p99_ms": deviation_ms[1],
    }


def period_deviation_ms(arrivals: list[float]) -> tuple[float, float]:
    """p50 and p99 of |telegram period − median period| (ms), periods taken between the
    arrivals of consecutive telegrams' last bytes; (nan, nan) with fewer than 3 telegrams."""
    if len(arrivals) < 3:
        return float("nan"), float("nan")
    periods = np.diff(arrivals)
    deviations = np.abs(periods - np.median(periods)) * 1000
    return float(np.percentile(deviations, 50)), float(np.percentile(deviations, 99))


def lms_scan_rates(
    scene: str | Path = "railway",
    sensor: str = "lms",
    bauds: tuple[int, ...] = tuple(BAUD_COMMANDS),
    resolutions_deg: tuple[float, ...] = (0.5, 1.0),
    duration_s: float = 5.0,
) -> dict:
    """Scans/s per baud × resolution through `lrf-emulator serve` over a pty.

    Every sensor of the scene is served on a pty in a temporary folder, so the
    measurement never meets a user's daemon on the scene's own endpoints.

    Returns {"scene", "sensor", "duration_s", "rows": [{"baud", "resolution_deg",
    "telegram_bytes", "scans", "measured_per_s", "limit_per_s", "ratio"}, ...]}.
    """
    with tempfile.TemporaryDirectory(prefix="lrf-bench-") as folder:
        with ServeProcess(scene, private_endpoints(scene, Path(folder))) as daemon:
            with LmsSerialClient(daemon.endpoint(sensor, "pty").path) as client:
                client.find_device_baud()
                rows = [
                    measure_stream(client, baud, resolution, duration_s)
                    for baud in bauds for resolution in resolutions_deg
                ]
    return {"scene": str(scene), "sensor": sensor, "duration_s": duration_s, "rows": rows}


def table_lines(result: dict) -> list[str]:
    """The measurement as a plain-text table for `lrf-emulator bench`."""
    lines = [
        f"LMS200 scans/s through serve over a pty ({result['scene']}, at least {result['duration_s']:g} s each)",
        f"{'baud':>7} {'res':>5} {'bytes':>5} {'scans':>5} {'measured/s':>10} {'limit/s':>8} {'ratio':>6}"
        f" {'period dev p50/p99 ms':>22}",
    ]
    for row in result["rows"]:
        lines.append(
            f"{row['baud']:>7} {row['resolution_deg']:>4g}° {row['telegram_bytes']:>5} {row['scans']:>5} "
            f"{row['measured_per_s']:>10.2f} {row['limit_per_s']:>8.2f} {row['ratio']:>6.3f}"
            f" {row['period_deviation_p50_ms']:>10.2f} / {row['period_deviation_p99_ms']:<9.2f}"
        )
    return lines


def bench_section(quick: bool) -> tuple[dict, list[str]]:
    """`lrf-emulator bench`'s section: (JSON data, table lines); `quick` measures 1 s per cell."""
    result = lms_scan_rates(duration_s=1.0 if quick else 5.0)
    return {"lms_scans_per_s": result}, table_lines(result)


def main() -> None:
    """`python -m emulator.bench.lms_rates`: the full table (about a minute)."""
    started = time.monotonic()
    print("\n".join(table_lines(lms_scan_rates())))
    print(f"({time.monotonic() - started:.0f} s)")


if __name__ == "__main__":
    main()
