"""The seed dataset's text log: one scan per line (paper §3.2).

"Each measurement is placed on a single line and consists of a timestamp and
pairs of angles (radians) and distances." Our exact form:

    # lrf-emulator log sensor=urg model=urg-04lx unit=mm
    12.300 -2.094395 0 -2.088259 1 ... 0.000000 2503 ...

- the timestamp is simulated time in seconds with 3 decimals (the device's
  millisecond resolution);
- each pair is the beam's angle in the sensor frame (radians, 6 decimals, 0 =
  straight ahead, positive to the left) and the device value as an integer,
  exactly as it went on the wire (URG: mm or an error code < 20; LMS200: mm or
  cm per `unit`, or a code 8183..8191), so error codes survive the round trip;
- the pairs are the beams the device measures, as its ROS driver publishes
  them (`record` writes `sensors.published`: the URG-04LX's steps 44..725,
  682 pairs; the LMS200 its window). The paper fixes what a line holds (a
  timestamp, then angle/distance pairs) but not which beams; reading accepts
  any pairs on the device's grid;
- lines starting with `#` are comments; the optional header comment names the
  sensor, model and unit as `key=value` words. Blank lines are ignored.

Writing what was read reproduces the file byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, TextIO

import numpy as np

from emulator.errors import UserError
from emulator.sensors.scan import Scan

HEADER_PREFIX = "# lrf-emulator log"
MAX_DEVICE_VALUE = 0xFFFF_FFFF  # what any unit's wire value fits in (a CoLa DIST channel of u32 at most): beyond it a log is garbage


@dataclass(frozen=True)
class LogHeader:
    """What the header comment says about the scans below it (all optional)."""

    sensor: str = ""
    model: str = ""
    unit: str = "mm"

    def line(self) -> str:
        return f"{HEADER_PREFIX} sensor={self.sensor} model={self.model} unit={self.unit}\n"


def format_scan(scan: Scan) -> str:
    """One log line (with its newline) for `scan`."""
    pairs = np.empty(2 * len(scan.values), dtype=object)
    pairs[0::2] = np.round(np.asarray(scan.angles_rad, dtype=float), 6) + 0.0  # no "-0.000000"
    pairs[1::2] = np.asarray(scan.values, dtype=np.int64).tolist()
    template = "%.3f" + " %.6f %d" * len(scan.values) + "\n"
    return template % (scan.timestamp_ms / 1000.0, *pairs)


def write_log(out: TextIO, scans: Iterable[Scan], header: LogHeader) -> int:
    """Write the header and one line per scan; return the number of scans."""
    out.write(header.line())
    count = 0
    for scan in scans:
        out.write(format_scan(scan))
        count += 1
    return count


@dataclass(frozen=True)
class Log:
    """A whole log: `times_s` (n,), `angles_rad` (n, m) and integer `values` (n, m)."""

    header: LogHeader
    times_s: np.ndarray
    angles_rad: np.ndarray
    values: np.ndarray

    def scans(self) -> list[Scan]:
        return [
            Scan(self.header.sensor, self.header.model, float(t), a, v, self.header.unit)
            for t, a, v in zip(self.times_s, self.angles_rad, self.values)
        ]


def _parse_header(line: str) -> LogHeader | None:
    if not line.startswith(HEADER_PREFIX):
        return None
    fields = dict(word.split("=", 1) for word in line[len(HEADER_PREFIX):].split() if "=" in word)
    return LogHeader(fields.get("sensor", ""), fields.get("model", ""), fields.get("unit", "mm"))


def read_log(path: str | Path) -> Log:
    """Parse a log file; any malformed line is a UserError naming file and line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        raise UserError(f"no such log file: {path}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise UserError(f"{path}: cannot read log: {error}") from None
    header = LogHeader()
    rows: list[np.ndarray] = []
    line_numbers: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            header = _parse_header(stripped) or header
            continue
        try:
            row = np.array(stripped.split(), dtype=float)
        except ValueError:
            raise UserError(f"{path.name}: line {number}: not a list of numbers") from None
        if row.size < 3 or row.size % 2 == 0 or not np.all(np.isfinite(row)):
            raise UserError(
                f"{path.name}: line {number}: expected a timestamp and (angle, distance) pairs"
            )
        rows.append(row)
        line_numbers.append(number)
    if not rows:
        raise UserError(f"{path.name}: no scans in log")
    width = rows[0].size
    for row, number in zip(rows, line_numbers):
        if row.size != width:
            raise UserError(
                f"{path.name}: line {number}: {(row.size - 1) // 2} pairs, "
                f"the first scan has {(width - 1) // 2}"
            )
    table = np.vstack(rows)
    values = table[:, 2::2]
    wrong = (values != np.round(values)) | (values < 0) | (values > MAX_DEVICE_VALUE)
    if np.any(wrong):
        bad = line_numbers[int(np.argmax(np.any(wrong, axis=1)))]
        raise UserError(f"{path.name}: line {bad}: distances must be whole device values, 0..{MAX_DEVICE_VALUE}")
    times = table[:, 0]
    if np.any(np.diff(times) <= 0):
        bad = line_numbers[int(np.argmax(np.diff(times) <= 0)) + 1]
        raise UserError(f"{path.name}: line {bad}: timestamps must increase")
    return Log(header, times, table[:, 1::2], values.astype(np.int64))
