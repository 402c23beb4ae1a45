"""`python -m adversary`: the same as the `adversary` command."""

import sys

from adversary.cli import main

sys.exit(main())
