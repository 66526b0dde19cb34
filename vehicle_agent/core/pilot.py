"""The vehicle's pilot: what a vehicle does with what its relay tells it, without any I/O.

A :class:`Pilot` is fed goals, stop commands, mode changes, drive commands, poses, link resets
and clock ticks, each with the time it happened (seconds, the vehicle's monotonic clock), and
answers with the event records of what it did (:mod:`app.protocol.events`), in order; each
:class:`~app.protocol.events.TwistSent` among them is a Twist to publish now. It composes the
twins: the manual gate (:class:`~vehicle_agent.core.manual.ManualDrive`: while an operator holds the
wheel, goals are dropped with ``why="manual"`` and drive commands steer, until the dead-man),
then the freshness gate (:class:`~vehicle_agent.core.freshness.GoalGate`: latest wins, stale goals
dropped), then the controller (:class:`~vehicle_agent.core.control.Controller`, with the control law
its profile names); every Twist, the operator's too, then passes the robot's limiter
(:class:`~vehicle_agent.core.limits.Limiter`: clamped to its top speeds, ramped within its
accelerations, a stop at once). A lost link, a mode change and a stop command halt the turtle.
The searching profiles record when a search for a lost target starts
(:class:`~app.protocol.events.SearchStarted`, and which way it turns) and how it ends
(:class:`~app.protocol.events.SearchEnded`: the target found, the search's time run out and the
vehicle stopped, or piloting stopped).

The adapters only move bytes: ``vehicle_agent/agent.py`` (aiortc, rosbridge or the in-process
simulator, the event log) and the browser vehicle page (``app/static/js/pages/vehicle.js``)
feed their pilot and act on its answers. The page's pilot is this module's twin,
``app/static/js/core/pilot.js``, and both run the shared sequences of
``tests/vehicle_agent/core/pilot_sequences.py`` (``tests/vehicle_agent/core/test_pilot.py`` here,
``e2e/test_pilot_js.py`` in Chromium), which also state the rules themselves.
"""

from __future__ import annotations

from app.protocol import channels
from app.protocol.channels import Mode, SearchStatus
from app.protocol.control import DEADMAN_S, TICK_S, for_robot
from app.protocol.events import (
    DriveReceived,
    GoalApplied,
    GoalDropped,
    ModeChanged,
    PilotEvent,
    SearchEnd,
    SearchEnded,
    SearchStarted,
    Side,
    TwistSent,
)
from app.protocol.robot import TURTLESIM, Robot
from vehicle_agent.core.control import ControlLaw, Controller, Goal, Pose, Profile, Twist
from vehicle_agent.core.frame_times import FrameTimes
from vehicle_agent.core.freshness import FreshnessRule, GoalGate
from vehicle_agent.core.limits import Limiter
from vehicle_agent.core.manual import ManualDrive


class Pilot:
    """One vehicle's pilot with one profile for one robot; every input answers with the records
    of what it did (a :class:`~app.protocol.events.TwistSent` is a Twist to publish).

    ``robot`` is the robot driven (default: a turtlesim): the pilot fits ``profile`` to it
    (:func:`app.protocol.control.for_robot`) and holds every command to its limits.
    """

    def __init__(
        self,
        profile: Profile,
        *,
        robot: Robot = TURTLESIM,
        deadman_s: float = DEADMAN_S,
        tick_s: float = TICK_S,
        freshness: FreshnessRule | None = None,
        law: ControlLaw | None = None,
    ) -> None:
        profile = for_robot(profile, robot)
        self.profile = profile
        self.tick_s = tick_s
        self.controller = Controller(profile, law)
        self.manual = ManualDrive(profile, deadman_s)
        # Between every command and the robot: its top speeds and accelerations.
        self.limiter = Limiter(robot.limits, tick_s)
        # When the vehicle's own camera took its recent frames: a goal names its frame.
        self.frames = FrameTimes()
        # Latest-wins on the lossy goal channel; reset for every new link.
        self.gate = GoalGate() if freshness is None else GoalGate(freshness)
        # When the last goal was applied on this link (its age rides the pose: link health).
        self._last_goal_at: float | None = None
        # A search ran out and stopped the vehicle, and nothing has steered it since.
        self._search_timed_out = False

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

    @property
    def search(self) -> SearchStatus | None:
        """How the search for a lost target stands, as the vehicle's pose tells the client:
        the side it turns to, ``timed_out`` once it ran out and stopped the vehicle (until a
        goal, a stop or a mode change), None when there is none."""
        if self.controller.search_since is not None:
            return self._search_side()
        return "timed_out" if self._search_timed_out else None

    def _search_side(self) -> Side:
        return "left" if self.controller.last_side > 0 else "right"

    def goal_age(self, now: float) -> float | None:
        """Seconds since the last goal applied on this link, None before the first."""
        return None if self._last_goal_at is None else now - self._last_goal_at

    # --- what the relay says ---------------------------------------------------------------

    def frame(self, frame: int, now: float) -> None:
        """The vehicle's own camera took its frame number ``frame`` (the number its frame tag
        carries) at ``now``: a goal found in it later takes its bearing from the heading then."""
        self.frames.add(frame, now)

    def goal(self, goal: channels.Goal, now: float) -> list[PilotEvent]:
        """A goal: dropped while manual, or by the freshness gate; else it steers, from the
        heading the vehicle had when its frame was taken (when the vehicle took that frame)."""
        if self.manual.manual:
            return [GoalDropped(seq=goal.seq, frame=goal.frame, why="manual", t=now)]
        verdict = self.gate.admit(goal.seq, goal.t, now)
        if verdict != "fresh":
            return [GoalDropped(seq=goal.seq, frame=goal.frame, why=verdict, t=now)]
        self._last_goal_at = now
        self._search_timed_out = False
        searching = self.controller.search_since
        applied = GoalApplied(
            seq=goal.seq,
            op=goal.op,
            frame=goal.frame,
            x=goal.x,
            y=goal.y,
            w=goal.w,
            h=goal.h,
            box_w=goal.boxW,
            box_h=goal.boxH,
            locked=goal.locked,
            t=now,
        )
        target = Goal(
            goal.x,
            goal.y,
            goal.w,
            goal.h,
            goal.seq,
            goal.frame,
            box_h=goal.boxH,
            target_height_m=goal.targetHeightM,
        )
        twist = self.controller.goal(target, now, self.frames.captured_at(goal.frame))
        return [applied, *self._searched(searching, "found", now), *self._sent(twist, now)]

    def stop(self, now: float) -> list[PilotEvent]:
        """The relay stopped piloting: the autopilot's turtle stops."""
        searching = self.controller.search_since
        twist = self.controller.stop()
        self._search_timed_out = False
        return [*self._searched(searching, "stopped", now), *self._sent(twist, now)]

    def mode_change(self, mode: Mode, operator: str | None, now: float) -> list[PilotEvent]:
        """The relay's mode. Whichever way it changes, the turtle stops first: the autopilot's
        last command must not outlive its goals, nor the operator's outlive the wheel."""
        stopped = self.manual.set_mode(mode, operator)
        if stopped is None:
            return []
        searching = self.controller.search_since
        self.controller.stop()
        self._search_timed_out = False
        changed = ModeChanged(mode=mode, operator=self.manual.operator, t=now)
        return [changed, *self._searched(searching, "stopped", now), *self._sent(stopped, now)]

    def drive(self, seq: int, linear: float, angular: float, now: float) -> list[PilotEvent]:
        """An operator's drive command: it steers in manual mode when it is the newest."""
        twist = self.manual.drive(seq, linear, angular, now)
        moving = twist is not None and not twist.is_zero
        received = DriveReceived(seq=seq, applied=twist is not None, moving=moving, t=now)
        return [received, *self._sent(twist, now)]

    # --- what the vehicle itself sees --------------------------------------------------------

    def pose(self, pose: Pose, now: float) -> list[PilotEvent]:
        """The turtle's pose: closed-loop profiles answer it (a search starts on it)."""
        searching = self.controller.search_since
        twist = self.controller.pose(pose, now)
        return [*self._searched(searching, "timed_out", now), *self._sent(twist, now)]

    def tick(self, now: float) -> list[PilotEvent]:
        """The clock: the goal timeout, the clock-driven profile's period, the dead-man, and the
        next step of a ramp under way."""
        searching = self.controller.search_since
        done = [
            *self._sent(self.controller.tick(now), now),
            *self._sent(self.manual.tick(now), now),
        ]
        searched = self._searched(searching, "timed_out", now)
        return [*searched, *(done or _record(self.limiter.tick(now), now))]

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
        if self.manual.manual:
            return self.mode_change("auto", None, now)
        return self.stop(now)

    def _searched(self, before: float | None, end: SearchEnd, now: float) -> list[PilotEvent]:
        """The record of a search that started or ended since the controller's search began at
        ``before`` (None: none was under way); ``end`` says how one that ended did."""
        since = self.controller.search_since
        if before is None and since is not None:
            return [SearchStarted(side=self._search_side(), t=now)]
        if before is not None and since is None:
            self._search_timed_out = end == "timed_out"
            return [SearchEnded(why=end, after_s=now - before, t=now)]
        return []

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
