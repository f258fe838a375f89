"""A virtual serial device: a pty whose slave is published under a symlink.

The daemon does not keep the slave open, so the master tells whether a client
has it open: with none, reads fail with EIO and poll() reports POLLHUP. While
no client is there we watch for one every `PRESENCE_POLL_S` (a master with no
slave is always "readable", so it cannot stay registered with the loop).
`tcgetattr(master)` returns the slave's termios: the client's baud.
"""

from __future__ import annotations

import array
import asyncio
import errno
import fcntl
import os
import re
import select
import termios
import tty
from pathlib import Path

from emulator.errors import UserError
from emulator.scene.endpoints import PtyAddress
from emulator.transport import Session
from emulator.transport.link import READ_SIZE, ClientSlot
from emulator.transport.outbox import DEFAULT_LIMIT_BYTES

PRESENCE_POLL_S = 0.015

# termios speed constant (B9600, B500000, ...) → bits per second
BAUD_OF_SPEED: dict[int, int] = {
    getattr(termios, name): int(name[1:]) for name in dir(termios) if re.fullmatch(r"B\d+", name)
}


def is_stale_pty_link(target: str) -> bool:
    """A link's target names a pty (/dev/pts/N) that is gone: its daemon died without removing it."""
    return re.fullmatch(r"/dev/pts/[0-9]+", target) is not None and not os.path.lexists(target)


class PtyEndpoint(ClientSlot):
    """Serves one session on a pty published at `address.path`.

    Received bytes are discarded while the client's termios speed differs from
    the session's baud (a wrong-rate line garbles). When the client closes the
    slave, the session is told once, unsent output and anything still queued
    in the pty are discarded, and the endpoint waits for the next client.
    """

    def __init__(
        self,
        address: PtyAddress,
        session: Session,
        *,
        limit_bytes: int = DEFAULT_LIMIT_BYTES,
    ) -> None:
        super().__init__(session, limit_bytes=limit_bytes)
        self.address = address
        self.link_path = Path(address.path).absolute()
        self.slave_name = ""
        self._master = -1
        self._hangup_poller = select.poll()
        self._presence_timer: asyncio.TimerHandle | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def open(self, loop: asyncio.AbstractEventLoop) -> str:
        """Create the pty and its symlink; returns the slave's name (/dev/pts/N)."""
        self._loop = loop
        self._refuse_existing_path()
        master, slave = os.openpty()
        try:
            tty.setraw(slave)  # no echo, no CR/LF rewriting: raw bytes both ways
            self.slave_name = os.ttyname(slave)
        finally:
            os.close(slave)
        os.set_blocking(master, False)
        self._master = master
        self._hangup_poller.register(master, select.POLLHUP)
        try:
            os.symlink(self.slave_name, self.link_path)  # fails if PATH appeared meanwhile: never replaced
        except OSError as error:
            self.close()
            raise UserError(f"{self.address}: cannot create {self.link_path}: {error.strerror}") from None
        self._watch_for_client()
        return self.slave_name

    def close(self) -> None:
        """Close the pty and remove the symlink (only if it is still ours)."""
        if self._presence_timer is not None:
            self._presence_timer.cancel()
            self._presence_timer = None
        self._disconnect()
        if self._master >= 0:
            self._hangup_poller.unregister(self._master)
            os.close(self._master)
            self._master = -1
        if self.slave_name and os.path.islink(self.link_path):
            if os.readlink(self.link_path) == self.slave_name:
                os.unlink(self.link_path)

    def client_baud(self) -> int | None:
        """The speed the client set on its end of the pty (bits per second)."""
        speed = termios.tcgetattr(self._master)[5]
        return BAUD_OF_SPEED.get(speed)

    def _refuse_existing_path(self) -> None:
        """Replace only a link a daemon that died left behind (to a /dev/pts/N that no longer
        exists); refuse anything else at PATH: another daemon's live link, a user's file."""
        if os.path.islink(self.link_path):
            target = os.readlink(self.link_path)
            if is_stale_pty_link(target):
                os.unlink(self.link_path)
                return
            raise UserError(
                f"{self.address}: {self.link_path} already exists (a symlink to {target}); "
                "another daemon may be serving it: remove it if not"
            )
        if os.path.lexists(self.link_path):
            raise UserError(f"{self.address}: {self.link_path} already exists and is not ours to replace")

    def _client_present(self) -> bool:
        return not any(event & select.POLLHUP for _, event in self._hangup_poller.poll(0))

    def _watch_for_client(self) -> None:
        self._presence_timer = None
        if self._master < 0:
            return
        if self._client_present():
            self._connect(
                self._loop,
                self._master,
                read=lambda: os.read(self._master, READ_SIZE),
                write=lambda data: os.write(self._master, data),
                on_lost=self._client_left,
                accepts_input=self._baud_matches,
                kernel_backlog=self._unread_by_client,
            )
        else:
            self._presence_timer = self._loop.call_later(PRESENCE_POLL_S, self._watch_for_client)

    def _baud_matches(self) -> bool:
        baud = self._session.baud
        return baud is None or self.client_baud() == baud

    def _unread_by_client(self) -> int:
        """Bytes waiting in the slave's input for the client to read. The master cannot tell
        (its TIOCOUTQ stays 0): FIONREAD on the slave, opened for the question, can; the
        pty's own buffers beyond it (≈ 18 KiB) only fill once that reads 4095."""
        try:
            slave = os.open(self.slave_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return 0
        try:
            count = array.array("i", [0])
            fcntl.ioctl(slave, termios.FIONREAD, count, True)
            return count[0]
        except OSError:
            return 0
        finally:
            os.close(slave)

    def _client_left(self) -> None:
        self._disconnect()
        self._discard_queued_bytes()
        self._session.disconnected()
        self._watch_for_client()

    def _discard_queued_bytes(self) -> None:
        """Bytes still in the pty for the old client would reach the next one: flush them from the
        slave side. Only those (the slave's input): a next client may already have opened it and
        written its first command, which must reach the device (a driver restarted at once lost it)."""
        try:
            slave = os.open(self.slave_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as error:
            if error.errno in (errno.ENOENT, errno.EIO):
                return
            raise
        try:
            termios.tcflush(slave, termios.TCIFLUSH)
        finally:
            os.close(slave)
