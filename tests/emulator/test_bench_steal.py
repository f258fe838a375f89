"""The bench's steal share: parsed from /proc/stat's aggregate line, measured between marks."""

import math
import os

from emulator.bench.steal import StealMeter, cpu_ticks, read_cpu_ticks, steal_share, steal_text

STAT = """cpu  100 5 50 800 10 1 2 32 7 0
cpu0 50 2 25 400 5 0 1 16 3 0
intr 12345
"""


def test_the_aggregate_line_gives_all_ticks_and_the_stolen_ones() -> None:
    assert cpu_ticks(STAT) == (100 + 5 + 50 + 800 + 10 + 1 + 2 + 32, 32)  # guest time is inside user: not counted twice


def test_a_text_without_steal_or_without_a_cpu_line_reads_as_nothing() -> None:
    assert cpu_ticks("cpu  1 2 3 4 5 6 7\n") == (0, 0)
    assert cpu_ticks("intr 5\n") == (0, 0)


def test_the_share_is_the_stolen_part_of_the_ticks_between_two_readings() -> None:
    assert steal_share((1000, 100), (1400, 200)) == 0.25
    assert math.isnan(steal_share((1000, 100), (1000, 100)))
    assert steal_text(0.25) == "steal 25%" and steal_text(math.nan) == "steal n/a"


def test_the_meter_measures_this_machine_between_its_first_and_last_mark() -> None:
    meter = StealMeter()
    assert math.isnan(meter.share)
    meter.mark()
    end = os.times().elapsed + 0.05
    while os.times().elapsed < end:  # busy: ticks pass on every core's clock
        pass
    meter.mark()
    total, _ = read_cpu_ticks()
    assert total > 0  # Linux: /proc/stat is there
    assert 0.0 <= meter.share <= 1.0
