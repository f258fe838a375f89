"""The control API of a running daemon (docs/control.md), its event log and `ctl`.

Owns the HTTP/WebSocket server on the daemon's loop (`server.py`), the
translation of request bodies and event-log lines into live events by the
scene loader's rules (`events.py`), the publishing of scans to WebSocket
clients (`scan_feed.py`) and the terminal client (`ctl.py`). It may import
emulator.scene, emulator.sensors, emulator.daemon and emulator.errors, and
aiohttp; nothing below it imports it: every front end (the live view, ctl,
tests) changes the world through this one way in.
"""
