"""`python -m emulator.validation FILE.md`: regenerate the validation report."""

import sys

from emulator.validation.report import main

sys.exit(main())
