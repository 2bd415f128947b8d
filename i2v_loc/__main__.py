"""``python -m i2v_loc``: the same as the ``i2v-loc`` command."""

import sys

from i2v_loc.cli import main

sys.exit(main())
