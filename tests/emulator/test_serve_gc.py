"""Once serving, the daemon keeps what it built at start-up out of the collector's sight: a full
collection then walks only what came after, instead of stopping the loop for 50-80 ms."""

from __future__ import annotations

from pathlib import Path

from emulator.bench.serve_process import ServeProcess, private_endpoints


def test_a_serving_daemon_has_frozen_its_start_up_objects(tmp_path: Path) -> None:
    with ServeProcess("railway", private_endpoints("railway", tmp_path)) as daemon:
        assert daemon.stats()["gc_frozen"] > 10_000  # the scene, world and sessions: ~44 000 objects
