"""`python -m riskmap`: the same as the `riskmap` command."""

import sys

from riskmap.cli import main

sys.exit(main())
