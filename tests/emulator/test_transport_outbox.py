"""The shared outbox: pacing arithmetic, bound and drop policy, interrupts (no I/O)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from emulator.transport.outbox import BITS_PER_BYTE, KERNEL_BACKLOG_BYTES, KERNEL_RECHECK_S, PACE_QUANTUM_S, Outbox
from protocols.device import Output


def drain(outbox: Outbox, start: float = 0.0, *, lateness_s: float = 0.0) -> tuple[bytes, float]:
    """Write everything as a link would, waking exactly when asked (plus `lateness_s`)."""
    now, written = start, bytearray()
    while outbox:
        data, wake_at = outbox.chunk(now)
        if data:
            written += data
            outbox.consume(len(data))
        else:
            assert wake_at is not None and wake_at > now
            now = wake_at + lateness_s
    return bytes(written), now


def test_unpaced_output_is_written_whole_at_once() -> None:
    outbox = Outbox()
    outbox.put(Output(b"VV\n00P\n\n"))
    assert outbox.chunk(5.0) == (b"VV\n00P\n\n", None)


def test_paced_output_takes_its_line_time_in_small_chunks() -> None:
    outbox = Outbox()
    payload = bytes(range(256)) * 4
    outbox.put(Output(payload, baud=9600))
    chunks = []
    now = 0.0
    while outbox:
        data, wake_at = outbox.chunk(now)
        if data:
            chunks.append(data)
            outbox.consume(len(data))
        else:
            now = wake_at
    line_time = len(payload) * BITS_PER_BYTE / 9600
    assert b"".join(chunks) == payload
    assert abs(now - line_time) <= PACE_QUANTUM_S + 1e-9
    assert max(map(len, chunks)) <= 9600 / BITS_PER_BYTE * PACE_QUANTUM_S + 1


def test_late_wake_ups_catch_up_so_the_average_rate_holds() -> None:
    outbox = Outbox()
    payload = b"x" * 3840  # 1 s at 38400
    outbox.put(Output(payload, baud=38400))
    written, end = drain(outbox, lateness_s=0.002)
    assert written == payload
    assert abs(end - 1.0) < 0.01


def test_outputs_are_paced_each_at_its_own_baud() -> None:
    outbox = Outbox()
    outbox.put(Output(b"a" * 96, baud=9600))  # 0.1 s: a reply at the old rate
    outbox.put(Output(b"b" * 384, baud=38400))  # 0.1 s at the new rate
    written, end = drain(outbox)
    assert written == b"a" * 96 + b"b" * 384
    assert abs(end - 0.2) <= PACE_QUANTUM_S + 1e-9


def test_an_idle_line_gives_no_credit_for_the_past() -> None:
    outbox = Outbox()
    outbox.put(Output(b"x" * 96, baud=9600))
    drain(outbox)
    outbox.put(Output(b"y" * 96, baud=9600))
    _, end = drain(outbox, start=10.0)
    assert abs(end - 10.1) <= PACE_QUANTUM_S + 1e-9


def telegram_end_times(period_s: float, size: int, baud: int, count: int, lateness_s: float) -> list[float]:
    """When the last byte of each of `count` telegrams leaves, one telegram put every
    `period_s` (as a streaming LMS200 makes them), the link waking `lateness_s` late."""
    outbox = Outbox()
    ends = []
    for index in range(count):
        now = index * period_s + lateness_s
        outbox.put(Output(b"T" * size, baud=baud, droppable=True))
        while outbox:
            data, wake_at = outbox.chunk(now)
            if data:
                outbox.consume(len(data))
                if not outbox:
                    ends.append(now + len(data) * BITS_PER_BYTE / baud)
            else:
                assert wake_at is not None
                now = wake_at + lateness_s
    return ends


@given(st.floats(0.0, 0.003))
def test_a_telegram_after_a_short_idle_gap_is_paced_like_every_other(lateness_s: float) -> None:
    """LMS200 at 500 kBd: 732-byte telegrams (14.6 ms) every 26.7 ms leave a 12 ms idle
    gap. Credit for that gap would send every other telegram in one burst (periods
    alternating 16/37 ms); without it every telegram takes the same course."""
    period = 2 / 75
    ends = telegram_end_times(period, 732, 500_000, 12, lateness_s)
    deviations = [abs(later - earlier - period) for earlier, later in zip(ends, ends[1:])]
    assert max(deviations) < 1e-6, deviations


def test_a_full_outbox_drops_whole_scans_oldest_first_and_keeps_replies() -> None:
    outbox = Outbox(limit_bytes=1000)
    outbox.put(Output(b"R" * 600))
    for index in range(4):
        outbox.put(Output(bytes([48 + index]) * 300, droppable=True))
    written, _ = drain(outbox)
    assert outbox.dropped == 3
    assert written == b"R" * 600 + b"3" * 300


def test_a_scan_that_started_going_out_is_never_torn() -> None:
    outbox = Outbox(limit_bytes=500)
    outbox.put(Output(b"A" * 400, droppable=True))
    data, _ = outbox.chunk(0.0)
    outbox.consume(10)
    outbox.put(Output(b"B" * 400, droppable=True))
    written, _ = drain(outbox)
    assert written == b"A" * 390
    assert outbox.dropped == 1


def test_interrupt_discards_everything_unsent_first() -> None:
    outbox = Outbox()
    outbox.put(Output(b"S" * 700, baud=9600, droppable=True))
    outbox.put(Output(b"T" * 700, baud=9600, droppable=True))
    data, _ = outbox.chunk(0.0)
    outbox.consume(len(data))
    outbox.put(Output(b"\x06reply", baud=9600, interrupt=True))
    written, _ = drain(outbox, start=1.0)
    assert written == b"\x06reply"
    assert outbox.pending_bytes == 0


outputs = st.lists(
    st.tuples(st.binary(min_size=1, max_size=300), st.booleans()),
    min_size=1,
    max_size=30,
)


@given(outputs, st.lists(st.integers(0, 400), max_size=60), st.integers(200, 2000))
def test_what_goes_out_is_whole_outputs_in_order_and_every_reply(
    items: list[tuple[bytes, bool]], write_sizes: list[int], limit: int
) -> None:
    """Whatever the kernel accepts at each write (partial writes), the byte stream is
    the concatenation of whole outputs in their order: dropped scans vanish whole."""
    outbox = Outbox(limit_bytes=limit)
    tagged = [Output(bytes([i % 256]) + data, droppable=droppable) for i, (data, droppable) in enumerate(items)]
    written = bytearray()
    sizes = iter(write_sizes)
    for output in tagged:
        outbox.put(output)
        if outbox.pending_bytes > limit:  # only replies and a started scan may hold it over
            assert all(not item.output.droppable or item.sent for item in outbox._queue)
        data, _ = outbox.chunk(0.0)
        count = min(len(data), next(sizes, 0))
        written += data[:count]
        outbox.consume(count)
    written += drain(outbox)[0]
    remaining = bytes(written)
    kept = []
    for output in tagged:
        if remaining.startswith(output.data):
            kept.append(output)
            remaining = remaining[len(output.data) :]
        else:
            assert output.droppable, "a reply was dropped"
    assert remaining == b""
    assert len(tagged) - len(kept) == outbox.dropped


class Kernel:
    """What the link's fd reports as written but not yet taken by the client."""

    def __init__(self) -> None:
        self.unread = 0

    def __call__(self) -> int:
        return self.unread


def scan(tag: bytes) -> Output:
    return Output(tag * (KERNEL_BACKLOG_BYTES + 100), droppable=True)


def test_a_scan_waits_in_the_outbox_while_the_kernel_holds_more_than_one_message() -> None:
    kernel = Kernel()
    outbox = Outbox(kernel_backlog=kernel)
    kernel.unread = KERNEL_BACKLOG_BYTES + 150
    outbox.put(scan(b"a"))
    assert outbox.chunk(1.0) == (b"", 1.0 + KERNEL_RECHECK_S)
    assert outbox.holding
    kernel.unread = KERNEL_BACKLOG_BYTES + 100  # one message: the reader is keeping up
    assert outbox.chunk(1.02) == (b"a" * (KERNEL_BACKLOG_BYTES + 100), None)
    assert not outbox.holding


def test_a_held_scan_gives_way_to_a_newer_scan_and_to_a_reply_without_reordering() -> None:
    kernel = Kernel()
    outbox = Outbox(kernel_backlog=kernel)
    kernel.unread = 10_000
    outbox.put(scan(b"a"))
    outbox.chunk(0.0)
    outbox.put(scan(b"b"))  # replaces the held one
    outbox.put(Output(b"REPLY"))  # never held back: the scan ahead of it is dropped
    outbox.put(scan(b"c"))
    assert outbox.chunk(0.0) == (b"REPLY", None)
    outbox.consume(5)
    assert outbox.chunk(0.0) == (b"", KERNEL_RECHECK_S)  # c is the newest: it waits
    kernel.unread = 0
    written, _ = drain(outbox)
    assert written == b"c" * (KERNEL_BACKLOG_BYTES + 100)
    assert outbox.dropped == 2


def test_a_scan_already_started_is_finished_whatever_the_kernel_holds() -> None:
    kernel = Kernel()
    outbox = Outbox(kernel_backlog=kernel)
    outbox.put(scan(b"a"))
    data, _ = outbox.chunk(0.0)
    outbox.consume(40)
    kernel.unread = 10_000
    outbox.put(scan(b"b"))
    assert outbox.chunk(0.0) == (b"a" * (KERNEL_BACKLOG_BYTES + 60), None)


def test_short_scans_keep_streaming_until_the_kernel_holds_kernel_backlog_bytes() -> None:
    kernel = Kernel()
    outbox = Outbox(kernel_backlog=kernel)
    kernel.unread = KERNEL_BACKLOG_BYTES
    outbox.put(Output(b"t" * 732, droppable=True))  # an LMS200 telegram
    assert outbox.chunk(0.0) == (b"t" * 732, None)
