"""`python -m cdpm_drake.cli`."""

import sys

from cdpm_drake.cli import main

sys.exit(main())
