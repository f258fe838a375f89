"""One connected client on a non-blocking file descriptor (a pty master or a TCP socket).

Reads go to the session; outputs go through an `Outbox`, written in order
without ever blocking the loop: paced writes wake on a timer, a full kernel
buffer wakes on writability. Both transports use this, through `ClientSlot`;
they differ only in how a client arrives and leaves.
"""

from __future__ import annotations

import array
import asyncio
import fcntl
import termios
import time
from typing import Callable

from emulator.transport import Session
from emulator.transport.outbox import DEFAULT_LIMIT_BYTES, Outbox
from emulator.transport.timer import TimerHandle, shared_timer
from protocols.device import Output

READ_SIZE = 65536
# Bytes of one client's input handed to its device per loop turn: a 64 KiB
# write of commands is worked through in slices, with every other client's
# reads, timers and writes served in between, and no more is read from the
# client meanwhile (the kernel's buffers push back on it).
INPUT_SLICE_BYTES = 512
# A slice whose device work takes longer than this makes the next slices smaller (halved, down to
# MIN_INPUT_SLICE_BYTES; doubled back once they are cheap): input costing much per byte (an LMS200's
# flood of STX, a CRC per candidate: 6 ms a 512-byte slice) holds the loop no longer than that a turn.
SLICE_CPU_TARGET_S = 0.001
MIN_INPUT_SLICE_BYTES = 16
# A client's device work (CPU of the loop thread spent on its input) may use at
# most this share of wall time, with bursts up to INPUT_CPU_BURST_S: a client
# flooding commands is slowed down (its input waits in the kernel, pushing back
# on it) instead of starving every other client and sensor of the loop.
INPUT_CPU_SHARE = 0.05
INPUT_CPU_BURST_S = 0.005


def unsent_bytes(fd: int) -> int:
    """Bytes written to `fd` that its reader has not taken yet, as far as this end's kernel
    knows (TIOCOUTQ, which is SIOCOUTQ on a TCP socket: sent but not yet acknowledged);
    0 when the kernel cannot tell."""
    count = array.array("i", [0])
    try:
        fcntl.ioctl(fd, termios.TIOCOUTQ, count, True)
    except OSError:
        return 0
    return count[0]


class Link:
    """Bytes between one client and its session until the client goes away.

    `read()` returns received bytes (b"" at end of stream) and `write(data)`
    the count written; both may raise BlockingIOError, and any other OSError
    (EIO on a pty master, ECONNRESET) means the client is gone. `accepts_input()`
    lets a transport discard bytes (a pty client at the wrong baud).
    `on_lost` runs once when the client goes away; `close()` never calls it.

    Input costs bounded work per loop turn: a read is fed to the session
    INPUT_SLICE_BYTES at a time (fewer while slices cost more than SLICE_CPU_TARGET_S), one slice
    per turn, and the client is not read
    again until its last read is used up; a client whose input has cost more
    than INPUT_CPU_SHARE of the loop's time waits until it is back within it. A slice the device holds
    (its answer reads a scan still being computed) stops the input until the device has taken it:
    the rest waits unread, as behind a slow unit. While more replies wait unread than
    the outbox holds, the client is not read until it has taken enough of them: its bytes wait in
    the kernel (TCP's window, the tty's buffer) and its writes block, as a device's flow control
    makes them; none is lost, and what the daemon holds stays bounded.
    An output that hangs up (a reboot) calls `on_hang_up` once everything before it has been
    written, if the transport can drop its client (TCP); nothing after it is sent.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        fd: int,
        *,
        read: Callable[[], bytes],
        write: Callable[[bytes], int],
        session: Session,
        on_lost: Callable[[], None],
        accepts_input: Callable[[], bool] = lambda: True,
        limit_bytes: int = DEFAULT_LIMIT_BYTES,
        kernel_backlog: Callable[[], int] | None = None,
        on_hang_up: Callable[[], None] | None = None,
    ) -> None:
        self.outbox = Outbox(limit_bytes, kernel_backlog)
        self._on_hang_up = on_hang_up
        self._hanging_up = False  # the device hung up: drop the client once the outbox is empty
        self.discarded_input = 0  # bytes dropped: a pty client at the wrong baud
        self._stalled = False  # input waits until the client has read the replies piled up
        self._held = False  # the device keeps a slice until it can answer it: input waits until it has
        self._loop = loop
        self._fd = fd
        self._read = read
        self._write = write
        self._session = session
        self._on_lost = on_lost
        self._accepts_input = accepts_input
        self._pace_timer: TimerHandle | None = None
        self._waiting_writable = False
        self._open = True
        self._unfed = memoryview(b"")  # read but not yet given to the session
        self._slice_bytes = INPUT_SLICE_BYTES  # what the next slice holds at most (smaller while slices cost much)
        self._feeding: asyncio.Handle | asyncio.TimerHandle | None = None
        self._cpu_credit = INPUT_CPU_BURST_S  # loop-thread CPU seconds this client may still spend now
        self._credit_at = loop.time()
        self.last_activity = loop.time()  # a byte read from or written to the client
        loop.add_reader(fd, self._on_readable)

    @property
    def is_open(self) -> bool:
        return self._open

    def idle_for(self) -> float:
        """Seconds since a byte last went either way."""
        return self._loop.time() - self.last_activity

    def send(self, outputs: list[Output]) -> None:
        if not self._open or self._hanging_up:
            return
        for output in outputs:
            if output.hang_up:
                if self._on_hang_up is None:
                    continue  # a link that cannot drop its client (a pty) keeps it
                self._hanging_up = True
                break  # nothing after it reaches this client
            self.outbox.put(output)
        if self.outbox.holding and self._pace_timer is not None:
            # the held output may now be replaced by these: look again at once, not on the timer
            self._pace_timer.cancel()
            self._pace_timer = None
        self._pump()

    def close(self) -> None:
        """Stop reading and writing; unsent output is discarded."""
        if not self._open:
            return
        self._open = False
        self._loop.remove_reader(self._fd)
        if self._feeding is not None:
            self._feeding.cancel()
            self._feeding = None
        self._unfed = memoryview(b"")
        self._stalled = False
        self._held = False
        if self._waiting_writable:
            self._loop.remove_writer(self._fd)
            self._waiting_writable = False
        if self._pace_timer is not None:
            self._pace_timer.cancel()
            self._pace_timer = None
        self.outbox.clear()

    def _lost(self) -> None:
        if self._open:
            self.close()
            self._on_lost()

    def _on_readable(self) -> None:
        try:
            data = self._read()
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._lost()
            return
        self.last_activity = self._loop.time()
        if not self._accepts_input():
            self.discarded_input += len(data)
            return
        self._unfed = memoryview(data)
        self._loop.remove_reader(self._fd)
        self._feed_slice()

    def _feed_slice(self) -> None:
        """Give the session one slice of what was read; the rest on a later loop turn."""
        self._feeding = None
        if not self._open:
            return
        if self.outbox.pending_bytes > self.outbox.limit_bytes:
            self._stalled = True  # fed again by _pump once the client has read enough
            return
        size = self._slice_bytes
        piece, self._unfed = self._unfed[:size], self._unfed[size:]
        started = time.thread_time()
        hold = self._session.received(bytes(piece))
        spent = time.thread_time() - started
        self._cpu_credit -= spent
        if spent > SLICE_CPU_TARGET_S:
            self._slice_bytes = max(MIN_INPUT_SLICE_BYTES, size // 2)
        elif spent < SLICE_CPU_TARGET_S / 4 and len(piece) == size:
            self._slice_bytes = min(INPUT_SLICE_BYTES, size * 2)
        if not self._open:
            return
        if hold is not None:  # the device keeps this slice until its scan is computed: nothing more until then
            self._held = True
            hold(self._released)
            return
        self._next_slice()

    def _released(self) -> None:
        """The device has taken the slice it held: go on with the client's input."""
        if self._open and self._held:
            self._held = False
            self._next_slice()

    def _next_slice(self) -> None:
        """Schedule the next slice (or the next read), within the client's share of the loop's CPU."""
        now = self._loop.time()
        self._cpu_credit = min(INPUT_CPU_BURST_S, self._cpu_credit + (now - self._credit_at) * INPUT_CPU_SHARE)
        self._credit_at = now
        wait_s = max(0.0, -self._cpu_credit / INPUT_CPU_SHARE)
        step = self._feed_slice if self._unfed else self._resume_reading
        self._feeding = self._loop.call_later(wait_s, step) if wait_s > 0 else self._loop.call_soon(step)

    def _resume_reading(self) -> None:
        self._feeding = None
        if self._open:
            self._loop.add_reader(self._fd, self._on_readable)

    def _on_writable(self) -> None:
        self._loop.remove_writer(self._fd)
        self._waiting_writable = False
        self._pump()

    def _on_pace_timer(self) -> None:
        self._pace_timer = None
        self._pump()

    def _pump(self) -> None:
        """Write as much as pacing and the kernel allow, then arrange to be called again."""
        if not self._open or self._waiting_writable or self._pace_timer is not None:
            return
        now = self._loop.time()
        while True:
            data, wake_at = self.outbox.chunk(now)
            if not data:
                if wake_at is None and self._hanging_up:
                    self.close()
                    self._on_hang_up()
                    return
                if wake_at is not None:
                    # the precise timer: asyncio's fires 0.2-3.5 ms late, which moved the end of
                    # each paced telegram by as much (LMS200 period deviation p99 ≈ 3.6 ms)
                    self._pace_timer = shared_timer(self._loop).call_at(wake_at, self._on_pace_timer)
                return
            try:
                written = self._write(data)
            except BlockingIOError:
                written = 0
            except OSError:
                self._lost()
                return
            self.outbox.consume(written)
            if written > 0:
                self.last_activity = now
            if self._stalled and self.outbox.pending_bytes <= self.outbox.limit_bytes:
                self._stalled = False
                self._feeding = self._loop.call_soon(self._feed_slice)
            if written < len(data):
                self._loop.add_writer(self._fd, self._on_writable)
                self._waiting_writable = True
                return


class ClientSlot:
    """An endpoint's one client at a time: the `Link` that ties it to the session.

    The pty and TCP endpoints derive from this so that a client is wired to the
    session, counted, fed and dropped the same way on both.
    """

    def __init__(self, session: Session, *, limit_bytes: int = DEFAULT_LIMIT_BYTES) -> None:
        self.clients_served = 0
        self._session = session
        self._limit_bytes = limit_bytes
        self._link: Link | None = None

    @property
    def connected(self) -> bool:
        return self._link is not None

    @property
    def link(self) -> Link | None:
        return self._link

    def send(self, outputs: list[Output]) -> None:
        """Queue outputs for the client; with no client they are discarded."""
        if self._link is not None:
            self._link.send(outputs)

    def _connect(
        self,
        loop: asyncio.AbstractEventLoop,
        fd: int,
        *,
        read: Callable[[], bytes],
        write: Callable[[bytes], int],
        on_lost: Callable[[], None],
        accepts_input: Callable[[], bool] = lambda: True,
        kernel_backlog: Callable[[], int] | None = None,
        on_hang_up: Callable[[], None] | None = None,
    ) -> None:
        """A client arrived on `fd`: link it to the session."""
        self.clients_served += 1
        self._link = Link(
            loop,
            fd,
            read=read,
            write=write,
            session=self._session,
            on_lost=on_lost,
            accepts_input=accepts_input,
            limit_bytes=self._limit_bytes,
            kernel_backlog=kernel_backlog,
            on_hang_up=on_hang_up,
        )

    def _disconnect(self) -> None:
        """Forget the client; unsent output is discarded (the session is not told)."""
        if self._link is not None:
            self._link.close()
            self._link = None
