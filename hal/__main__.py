"""``python -m servotau.hal --robot module:callable ...``: serve a robot (see servotau.hal.robot.server)."""

import sys

from .robot.cli import main

sys.exit(main())
