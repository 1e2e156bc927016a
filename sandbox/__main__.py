"""``python -m sandbox`` runs the command-line interface."""

import sys

from sandbox.cli import main

sys.exit(main())
