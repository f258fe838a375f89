"""Watching a running daemon: the browser view (viser) and Foxglove live.

Readers of the world: they take the scans the daemon hands to its devices
(`feed.LiveFeed`, fed from the scan caches) and the world's state at the
clock's now, and draw them at a bounded rate, never on the daemon's loop: the
browser view and the Foxglove/MCAP publisher each run in a process of their
own. They change the world only through the control API. They may import `emulator.recording` (Foxglove channels, how the scene looks),
`emulator.scene`, `emulator.sensors` and `emulator.daemon`; nothing below
imports them (the `serve` command wires them in).
"""
