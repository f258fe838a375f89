"""`lrf-emulator bench`: every measurement of this machine's speed, and the clients it measures with.

`sections` holds the bench sections (rays, scans, transport, lms-rates,
memory); `transport_latency` and `lms_rates` drive a real `serve` process
started by `serve_process` through real clients (`lms_client` speaks LMS200
telegrams over a pty). The tests reuse these clients. It may import
everything; nothing but `commands.bench` and the tests imports it.
"""
