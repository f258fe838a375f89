"""`lrf-emulator bench`: every measurement of this machine's speed, and the clients it measures with.

`sections` holds the bench sections (rays, scans, transport, lms-rates,
memory); `transport_latency` and `lms_rates` drive a real `serve` process
started by `serve_process` through real clients (`lms_client` speaks LMS200
telegrams over a pty). `slam` runs SLAM end to end with MRPT's unmodified
tools (`mrpt`: rawlog-grabber, rawlog-edit, icp-slam) and scores the path
against the ground truth (`trajectory`); `slam_report` writes
docs/slam-in-smoke.md. The tests reuse these clients. It may import
everything; nothing but `commands.bench` and the tests imports it.
"""
