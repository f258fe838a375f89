"""A flood of commands costs the URG-04LX bounded memory and bounded work per cycle point."""

from __future__ import annotations

import numpy as np

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.device import MAX_QUEUED_COMMANDS


def flat_source(t: float) -> Scan:
    return Scan("urg", "URG-04LX", t, np.zeros(769), np.full(769, 1000))


def test_commands_beyond_the_queue_are_lost_like_an_overflowing_buffer() -> None:
    device = UrgDevice(flat_source)  # real timing: commands wait for the next cycle point
    assert device.receive(b"VV\n" * 5000, 1.001) == []
    assert device.lost_commands == 5000 - MAX_QUEUED_COMMANDS
    replies = device.poll(1.2)
    assert len(replies) == MAX_QUEUED_COMMANDS
    assert all(reply.data.startswith(b"VV\n00P\n") for reply in replies)
    assert device.poll(1.3) == [] and device.next_deadline() is None
