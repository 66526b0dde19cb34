"""``python -m vehicle_agent``: the same code as ``autopilot vehicle``."""

import sys

from app.cli import main

raise SystemExit(main(["vehicle", *sys.argv[1:]]))
