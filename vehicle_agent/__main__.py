"""``python -m vehicle_agent``: the same code as ``autopilot vehicle``, without the server's CLI."""

import argparse

from app.supervise import configure_logging
from vehicle_agent import cli

parser = argparse.ArgumentParser(prog="python -m vehicle_agent", description=cli.__doc__)
parser.add_argument("-v", "--verbose", action="store_true", help="log at DEBUG level")
cli.add_arguments(parser)
args = parser.parse_args()
configure_logging(args.verbose)
raise SystemExit(cli.run(args))
