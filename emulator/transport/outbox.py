"""Whole messages waiting for one client: bounded, written in order, paced at their baud.

Shared by every transport. The outbox decides *what* may be written *when*
(wall time); the link that owns it does the writing.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Callable

from protocols.device import Output

BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit
# A paced line is fed this far ahead, so bytes leave in ≈ 8 ms chunks: 24 wake-ups for an
# LMS200 telegram at 38400 baud, and the client's longest silence inside a telegram (a
# chunk plus a late wake-up) stays under the LMS200's 14 ms inter-byte gap limit.
PACE_QUANTUM_S = 0.008
CATCH_UP_S = 0.02  # a late wake-up inside an output may catch up this much
DEFAULT_LIMIT_BYTES = 16 * 1024
# While a droppable output is held because the kernel still queues earlier bytes for the
# client, the queue is looked at again this often (or sooner, when something is put).
KERNEL_RECHECK_S = 0.02
# A droppable output is held while the kernel holds more unread bytes than it has, or than
# this: short telegrams on a slow line keep streaming into a host's buffer like a real line's
# (a 9600 Bd LMS200 client pausing 2 s still finds what the line carried meanwhile).
KERNEL_BACKLOG_BYTES = 2048


@dataclass(eq=False)
class _Pending:
    output: Output
    sent: int = 0
    dropped: bool = False  # shed while waiting: skipped when it reaches the head


class Outbox:
    """Outputs not yet written, with the line-rate schedule of what was.

    Bounded: when more than `limit_bytes` wait (the client is not reading),
    whole droppable outputs that have not started are dropped, oldest first,
    like a real device whose full line skips scans. Replies are never dropped.
    Every put costs O(1) amortised: the droppable outputs are also kept in a
    queue of their own, each is shed at most once and a shed one stays in the
    main queue, marked, until it reaches the head (walking the whole queue on
    every put once replies had piled up made one 64 KiB write cost 36 s).

    With `kernel_backlog` (bytes written to the fd that the client has not yet
    taken), a droppable output is not started while the kernel still holds more
    than one such output (or KERNEL_BACKLOG_BYTES): it waits here, where a newer output can still replace
    it, instead of in the kernel, where it would reach a reader resuming after a
    stall before any fresh one. A held output is dropped as soon as anything
    newer waits behind it, so a reply is never held back and what goes out
    keeps its order.
    """

    def __init__(
        self, limit_bytes: int = DEFAULT_LIMIT_BYTES, kernel_backlog: Callable[[], int] | None = None
    ) -> None:
        self.limit_bytes = limit_bytes
        self.dropped = 0  # whole outputs dropped because the client was not reading
        self.holding = False  # the head is a droppable output waiting for the kernel to drain
        self._kernel_backlog = kernel_backlog
        self._queue: deque[_Pending] = deque()
        self._droppable: deque[_Pending] = deque()  # the droppable ones among them, oldest first
        self._pending_bytes = 0
        self._line_free_at = float("-inf")  # wall time the paced bytes written so far have left

    @property
    def pending_bytes(self) -> int:
        return self._pending_bytes

    def __bool__(self) -> bool:
        self._skip_dropped()
        return bool(self._queue)

    def put(self, output: Output) -> None:
        """Queue one whole output; an interrupting one first discards all unsent output."""
        if output.interrupt:
            self.clear()
        if not output.data:
            return
        pending = _Pending(output)
        self._queue.append(pending)
        if output.droppable:
            self._droppable.append(pending)
        self._pending_bytes += len(output.data)
        if self._pending_bytes > self.limit_bytes:
            self._shed()

    def clear(self) -> None:
        """Forget everything unsent (interrupt, or the client went away)."""
        self._queue.clear()
        self._droppable.clear()
        self._pending_bytes = 0

    def chunk(self, now: float) -> tuple[bytes, float | None]:
        """What may be written at wall time `now`: (bytes, None), or (b"", wake-up time)
        when pacing or a backlog in the kernel holds the line, or (b"", None) when nothing waits."""
        self.holding = False
        self._skip_dropped()
        if not self._queue:
            return b"", None
        head = self._queue[0]
        if head.output.droppable and head.sent == 0 and self._kernel_backlog is not None:
            backlog = self._kernel_backlog()
            while head.output.droppable and head.sent == 0 and backlog > max(len(head.output.data), KERNEL_BACKLOG_BYTES):
                if len(self._queue) == 1:
                    self.holding = True
                    return b"", now + KERNEL_RECHECK_S
                self._drop_head()
                head = self._queue[0]
        remaining = memoryview(head.output.data)[head.sent :]
        baud = head.output.baud
        if baud is None:
            return bytes(remaining), None
        if self._line_free_at > now:
            return b"", self._line_free_at
        if head.sent == 0 or self._line_free_at < now - CATCH_UP_S:
            # The line is idle: an output starting now earns no credit for the past (else a
            # telegram following a short gap leaves in one burst and the next is paced: the
            # telegram period alternates). Only a late wake-up inside an output catches up.
            self._line_free_at = now
        allowed = int((now + PACE_QUANTUM_S - self._line_free_at) * baud / BITS_PER_BYTE)
        return bytes(remaining[: max(1, allowed)]), None

    def consume(self, count: int) -> None:
        """`count` bytes of the head output were written."""
        if count <= 0:
            return
        head = self._queue[0]
        head.sent += count
        self._pending_bytes -= count
        if head.output.baud is not None:
            self._line_free_at += count * BITS_PER_BYTE / head.output.baud
        if head.sent >= len(head.output.data):
            self._queue.popleft()
            if self._droppable and self._droppable[0] is head:
                self._droppable.popleft()

    def _shed(self) -> None:
        """Drop droppable outputs that have not started, oldest first, until under the limit."""
        while self._pending_bytes > self.limit_bytes and self._droppable:
            item = self._droppable.popleft()
            if item.sent:
                continue  # started: it goes out whole
            item.dropped = True
            self._pending_bytes -= len(item.output.data)
            self.dropped += 1

    def _drop_head(self) -> None:
        """Drop the head output (droppable, not started): something newer waits behind it."""
        head = self._queue.popleft()
        if self._droppable and self._droppable[0] is head:
            self._droppable.popleft()
        self._pending_bytes -= len(head.output.data)
        self.dropped += 1
        self._skip_dropped()

    def _skip_dropped(self) -> None:
        while self._queue and self._queue[0].dropped:
            self._queue.popleft()
