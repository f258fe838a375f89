"""keep_freed_memory: large numpy temporaries are reused instead of faulted in afresh each time."""

from __future__ import annotations

import subprocess
import sys

PROGRAM = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from emulator.daemon.memory import keep_freed_memory
    assert keep_freed_memory()
source = np.random.default_rng(0).random(500_000)
index = np.arange(len(source))[::-1].copy()
def one_scan():  # several 4 MB temporaries alive at once, then all freed, as in a scan
    kept = [source.take(index) for _ in range(6)]
    del kept
one_scan()  # the first round faults its pages in either way
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    one_scan()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def minor_faults(mode: str) -> int:
    result = subprocess.run([sys.executable, "-c", PROGRAM, mode], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return int(result.stdout)


def test_kept_memory_spares_the_page_faults_of_repeated_large_temporaries() -> None:
    assert minor_faults("default") > 20 * 1000  # the temporaries faulted in again every round (~5900 pages)
    assert minor_faults("keep") < 500
