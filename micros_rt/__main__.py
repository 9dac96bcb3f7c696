"""``python -m micros_rt ...`` is the ``micros-rt`` command."""

import sys

from .cli import main

sys.exit(main())
