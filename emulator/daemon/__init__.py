"""The daemon: every sensor of a scene served on its endpoints from one asyncio loop.

`service` wires sensors, protocol devices and transports together and runs
them; `scan_cache` computes each sensor's scans once, off the loop and ahead
of time; `clock` maps simulated time to wall time. It may import everything
of the flow below it (scene, optics, sensors, protocols, transport), never a
front end (control, view, commands).
"""
