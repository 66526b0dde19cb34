"""argparse types for the numbers the commands take, so that every command refuses the same way.

``float()`` accepts ``nan`` and ``inf``, and ``int()`` any size: a goal timeout of ``nan`` would
never expire and a port of 70000 fails deep inside the server. These types turn such a value
into argparse's one-line usage error instead. The ``--profile``, ``--robot`` and ``--token``
options are declared here too, so that every command lists the same profiles and robots with
the same defaults and reads its token the same way. Imports only the protocol core and the
robot file reader, so the agent and the tools can all use it.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Sequence
from typing import Any

from app import robot_file
from app.protocol import control, relay_profiles, robot, tokens
from app.protocol.rooms import Role


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, not {text!r}")
    return value


def positive_number(text: str) -> float:
    """A finite number > 0."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, not {text!r}")
    return value


def non_negative_number(text: str) -> float:
    """A finite number >= 0."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, not {text!r}")
    return value


def _whole(text: str, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, not {text!r}") from None
    if value < least:
        raise argparse.ArgumentTypeError(f"expected a whole number >= {least}, not {text!r}")
    return value


def positive_integer(text: str) -> int:
    """A whole number >= 1."""
    return _whole(text, 1)


def non_negative_integer(text: str) -> int:
    """A whole number >= 0."""
    return _whole(text, 0)


def port(text: str) -> int:
    """A TCP port, 1 to 65535."""
    value = positive_integer(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"expected a port from 1 to 65535, not {text!r}")
    return value


def add_vehicle_profile(parser: argparse.ArgumentParser) -> None:
    """``--profile``: one of the vehicle profiles (:data:`app.protocol.control.PROFILES`)."""
    parser.add_argument(
        "--profile",
        choices=sorted(control.PROFILES),
        default=control.DEFAULT_PROFILE,
        help="vehicle profile: default (turn in place), thesis"
        f" ({control.PROFILES['thesis'].period_s * 1000:.0f} ms pacing), follow (drive to the"
        " target and keep a standoff), onboard (a robot that carries its camera: steer the"
        " target's bearing to zero, keep a standoff, search when it is lost)",
    )


class RobotOption(argparse.Action):
    """``--robot NAME|FILE`` read into the robot it names. A bad one ends the command with exit
    status 2 and the one line naming the file's bad key: as a ``type`` error, argparse would put
    its whole usage block before that line."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        try:
            chosen = robot_file.robot_named(str(values))
        except robot.RobotError as exc:
            parser.exit(2, f"{parser.prog}: error: argument {option_string}: {exc}\n")
        setattr(namespace, self.dest, chosen)


def add_robot_option(parser: argparse.ArgumentParser, purpose: str) -> None:
    """``--robot NAME|FILE``: a preset of :data:`app.protocol.robot.PRESETS` or a TOML file."""
    parser.add_argument(
        "--robot",
        action=RobotOption,
        default=robot.PRESETS[robot.DEFAULT_ROBOT],
        metavar="NAME|FILE",
        help=f"{purpose}: {', '.join(robot.PRESETS)} or a TOML description file"
        f" (docs/robots.md; default {robot.DEFAULT_ROBOT})",
    )


def add_relay_profile(parser: argparse.ArgumentParser, purpose: str) -> None:
    """``--profile``: one of the relay profiles (:data:`app.protocol.relay_profiles.PROFILES`)."""
    parser.add_argument(
        "--profile",
        choices=relay_profiles.PROFILES,
        default=relay_profiles.DEFAULT_PROFILE,
        help=f"{purpose} (default: {relay_profiles.DEFAULT_PROFILE})",
    )


def add_token_option(parser: argparse.ArgumentParser, role: Role) -> None:
    """``--token``: a token for ``role`` in the room, from ``autopilot token``; by default read
    from the environment, so that it stays out of the process list."""
    parser.add_argument(
        "--token",
        default=os.environ.get(tokens.ACCESS_TOKEN_ENV),
        help=f"{role} token for the room, from `autopilot token` "
        f"(default: ${tokens.ACCESS_TOKEN_ENV})",
    )
