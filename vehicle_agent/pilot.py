"""The vehicle's pilot: what a vehicle does with what its relay tells it, without any I/O.

A :class:`Pilot` is fed goals, stop commands, mode changes, drive commands, poses, link resets
and clock ticks, each with the time it happened (seconds, the vehicle's monotonic clock), and
answers with the event records of what it did (:mod:`app.protocol.events`), in order; each
:class:`~app.protocol.events.TwistSent` among them is a Twist to publish now. It composes the
twins: the manual gate (:class:`~vehicle_agent.manual.ManualDrive`: while an operator holds the
wheel, goals are dropped with ``why="manual"`` and drive commands steer, until the dead-man),
then the freshness gate (:class:`~vehicle_agent.freshness.GoalGate`: latest wins, stale goals
dropped), then the controller (:class:`~vehicle_agent.control.Controller`, with the control law
its profile names); every Twist, the operator's too, then passes the robot's limiter
(:class:`~vehicle_agent.limits.Limiter`: clamped to its top speeds, ramped within its
accelerations, a stop at once). A lost link, a mode change and a stop command halt the turtle.

The adapters only move bytes: ``vehicle_agent/agent.py`` (aiortc, rosbridge or the in-process
simulator, the event log) and the browser vehicle page (``app/static/js/pages/vehicle.js``)
feed their pilot and act on its answers. The page's pilot is this module's twin,
``app/static/js/core/pilot.js``, and both run the shared sequences of
``tests/vehicle_agent/pilot_sequences.py`` (``tests/vehicle_agent/test_pilot.py`` here,
``e2e/test_pilot_js.py`` in Chromium), which also state the rules themselves.
"""

from __future__ import annotations

from app.protocol import channels
from app.protocol.channels import Mode
from app.protocol.control import DEADMAN_S, TICK_S
from app.protocol.events import (
    DriveReceived,
    GoalApplied,
    GoalDropped,
    ModeChanged,
    PilotEvent,
    TwistSent,
)
from app.protocol.robot import TURTLESIM, Limits
from vehicle_agent.control import ControlLaw, Controller, Goal, Pose, Profile, Twist
from vehicle_agent.freshness import FreshnessRule, GoalGate
from vehicle_agent.limits import Limiter
from vehicle_agent.manual import ManualDrive


class Pilot:
    """One vehicle's pilot with one profile; every input answers with the records of what it
    did (a :class:`~app.protocol.events.TwistSent` is a Twist to publish).

    ``profile`` is the profile as fitted to the robot (:func:`app.protocol.control.for_robot`),
    ``limits`` the robot's (default: turtlesim's, which nothing the profiles command exceeds).
    """

    def __init__(
        self,
        profile: Profile,
        *,
        limits: Limits = TURTLESIM.limits,
        deadman_s: float = DEADMAN_S,
        tick_s: float = TICK_S,
        freshness: FreshnessRule | None = None,
        law: ControlLaw | None = None,
    ) -> None:
        self.profile = profile
        self.tick_s = tick_s
        self.controller = Controller(profile, law)
        self.manual = ManualDrive(profile, deadman_s)
        # Between every command and the robot: its top speeds and accelerations.
        self.limiter = Limiter(limits, tick_s)
        # Latest-wins on the lossy goal channel; reset for every new link.
        self.gate = GoalGate() if freshness is None else GoalGate(freshness)
        # When the last goal was applied on this link (its age rides the pose: link health).
        self._last_goal_at: float | None = None

    @property
    def mode(self) -> Mode:
        """``manual`` while an operator holds the wheel, else ``auto``."""
        return self.manual.mode

    @property
    def operator(self) -> str | None:
        """Who holds the wheel, in manual mode."""
        return self.manual.operator

    @property
    def active(self) -> bool:
        """True while goals steer the turtle (between the first goal and a stop)."""
        return self.controller.active

    def goal_age(self, now: float) -> float | None:
        """Seconds since the last goal applied on this link, None before the first."""
        return None if self._last_goal_at is None else now - self._last_goal_at

    # --- what the relay says ---------------------------------------------------------------

    def goal(self, goal: channels.Goal, now: float) -> list[PilotEvent]:
        """A goal: dropped while manual, or by the freshness gate; else it steers."""
        if self.manual.manual:
            return [GoalDropped(seq=goal.seq, frame=goal.frame, why="manual", t=now)]
        verdict = self.gate.admit(goal.seq, goal.t, now)
        if verdict != "fresh":
            return [GoalDropped(seq=goal.seq, frame=goal.frame, why=verdict, t=now)]
        self._last_goal_at = now
        applied = GoalApplied(
            seq=goal.seq,
            op=goal.op,
            frame=goal.frame,
            x=goal.x,
            y=goal.y,
            w=goal.w,
            h=goal.h,
            t=now,
        )
        target = Goal(goal.x, goal.y, goal.w, goal.h, goal.seq, goal.frame)
        return [applied, *self._sent(self.controller.goal(target, now), now)]

    def stop(self, now: float) -> list[PilotEvent]:
        """The relay stopped piloting: the autopilot's turtle stops."""
        return self._sent(self.controller.stop(), now)

    def mode_change(self, mode: Mode, operator: str | None, now: float) -> list[PilotEvent]:
        """The relay's mode. Whichever way it changes, the turtle stops first: the autopilot's
        last command must not outlive its goals, nor the operator's outlive the wheel."""
        stopped = self.manual.set_mode(mode, operator)
        if stopped is None:
            return []
        self.controller.stop()
        changed = ModeChanged(mode=mode, operator=self.manual.operator, t=now)
        return [changed, *self._sent(stopped, now)]

    def drive(self, seq: int, linear: float, angular: float, now: float) -> list[PilotEvent]:
        """An operator's drive command: it steers in manual mode when it is the newest."""
        twist = self.manual.drive(seq, linear, angular, now)
        moving = twist is not None and not twist.is_zero
        received = DriveReceived(seq=seq, applied=twist is not None, moving=moving, t=now)
        return [received, *self._sent(twist, now)]

    # --- what the vehicle itself sees --------------------------------------------------------

    def pose(self, pose: Pose, now: float) -> list[PilotEvent]:
        """The turtle's pose: closed-loop profiles answer it."""
        return self._sent(self.controller.pose(pose, now), now)

    def tick(self, now: float) -> list[PilotEvent]:
        """The clock: the goal timeout, the clock-driven profile's period, the dead-man, and the
        next step of a ramp under way."""
        done = [
            *self._sent(self.controller.tick(now), now),
            *self._sent(self.manual.tick(now), now),
        ]
        return done or _record(self.limiter.tick(now), now)

    def next_tick(self, now: float) -> float:
        """Seconds from ``now`` until :meth:`tick` is due: every ``tick_s``, and at once when
        the goal timeout or the dead-man falls due sooner, so a stop goes out on time."""
        waits = (self.controller.until_timeout(now), self.manual.until_deadman(now))
        return min([self.tick_s, *(w for w in waits if w is not None)])

    # --- the link ----------------------------------------------------------------------------

    def new_link(self, now: float) -> list[PilotEvent]:
        """A new link to a relay: halted, and everything numbered per link starts again (the
        relay's goal and drive seq; a new relay knows of no operator)."""
        halted = self.halt(now)
        self.gate.reset()
        self.manual.reset_link()
        self._last_goal_at = None
        return halted

    def halt(self, now: float) -> list[PilotEvent]:
        """Stop at once, autopilot or operator: the link that carried the commands is gone (or
        the vehicle is stopping). Back in auto mode."""
        stopped = self.controller.stop()
        if not self.manual.manual:
            return self._sent(stopped, now)
        return self.mode_change("auto", None, now)

    def _sent(self, twist: Twist | None, now: float) -> list[PilotEvent]:
        """The record of publishing ``twist`` (None: nothing to publish) within the limits."""
        return [] if twist is None else _record(self.limiter.command(twist, now), now)


def _record(twist: Twist | None, now: float) -> list[PilotEvent]:
    if twist is None:
        return []
    return [
        TwistSent(
            seq=twist.seq, frame=twist.frame, linear=twist.linear_x, angular=twist.angular_z, t=now
        )
    ]
