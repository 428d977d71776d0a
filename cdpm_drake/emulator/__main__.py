"""`python -m cdpm_drake.emulator`."""

import sys

from cdpm_drake.emulator import main

sys.exit(main())
