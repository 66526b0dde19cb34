"""The operator's wheel at the vehicle: mode, drive commands and the dead-man.

The rules are those of docs/architecture.md, "Who holds the wheel".

Sans-I/O, like :mod:`vehicle_agent.core.control`: a :class:`ManualDrive` is told the mode the relay
set, each drive command and the clock (the time given with each), and answers with the
:class:`Twist` to publish, if any. While manual, goals are the caller's to ignore
(:attr:`ManualDrive.manual`; the pilot drops them) and only drive commands move the turtle,
scaled to the profile's manual speeds. A vehicle that moves on a drive command and hears none for
the dead-man time (``DEADMAN_S`` in :mod:`app.protocol.control`, given to the constructor) stops
(one zero Twist). The browser vehicle page's ``core/manual.js`` is a port of this module, checked
against it (tests/vehicle_agent/core/manual_sequences.py, e2e/test_manual_js.py).
"""

from __future__ import annotations

from app.protocol.channels import Mode
from vehicle_agent.core.control import ZERO_TWIST, Profile, Twist


def _unit(value: float) -> float:
    return max(-1.0, min(1.0, value))


class ManualDrive:
    """Mode, the newest drive command and the dead-man of one vehicle."""

    def __init__(self, profile: Profile, deadman_s: float) -> None:
        self.profile = profile
        self.deadman_s = deadman_s
        self.mode: Mode = "auto"
        self.operator: str | None = None
        self._last_seq = 0
        self._last_at = 0.0
        self._moving = False

    @property
    def manual(self) -> bool:
        """True while an operator holds the wheel: goals must not steer."""
        return self.mode == "manual"

    def set_mode(self, mode: Mode, operator: str | None) -> Twist | None:
        """The relay's mode; a change of mode stops the turtle first (zero Twist)."""
        changed = mode != self.mode
        self.mode, self.operator = mode, operator if mode == "manual" else None
        if not changed:
            return None
        self._last_seq = 0  # the relay numbers each operator's commands afresh
        self._moving = False
        return ZERO_TWIST

    def reset_link(self) -> None:
        """A new link to a relay: back to auto (a new relay knows of no operator), seq afresh."""
        self.mode, self.operator = "auto", None
        self._last_seq = 0
        self._moving = False

    def drive(self, seq: int, linear: float, angular: float, now: float) -> Twist | None:
        """A drive command at ``now``; its Twist, or None when not manual or not the newest
        command."""
        if not self.manual or seq <= self._last_seq:
            return None
        self._last_seq = seq
        self._last_at = now
        twist = Twist(
            _unit(linear) * self.profile.manual_linear,
            _unit(angular) * self.profile.manual_angular,
        )
        self._moving = not twist.is_zero
        return twist

    def tick(self, now: float) -> Twist | None:
        """The dead-man: the zero Twist once no command came for ``deadman_s`` while moving."""
        if self._moving and now - self._last_at >= self.deadman_s:
            self._moving = False
            return ZERO_TWIST
        return None

    def until_deadman(self, now: float) -> float | None:
        """Seconds until the dead-man stops the turtle, None while it is not moving."""
        if not self._moving:
            return None
        return max(0.0, self._last_at + self.deadman_s - now)
