"""Recordings: scans written to files and files served as sensors.

`textlog` reads and writes the paper's dataset format; `replay_sources` are
sensor-like objects that give back a log's scans to a protocol device. It may
import `emulator.sensors` (the `Scan`) and below; the daemon and the commands
use it, never the other way round.
"""
