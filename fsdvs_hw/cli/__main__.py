"""``python -m fsdvs_hw.cli``: the ``fsdvs-hw`` command."""

import sys

from . import console

sys.exit(console())
