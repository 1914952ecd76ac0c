"""``python -m servotau.hal --robot module:callable ...``: serve a robot (see servotau.hal.server)."""

import sys

from .server import main

sys.exit(main())
