"""Puts `tests/` on the import path so every test can import `support` (tests/support/)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
