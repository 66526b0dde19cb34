"""The control laws and the controller that paces them (docs/architecture.md, "Vehicle control").

Sans-I/O: a :class:`Controller` is fed goals, poses and clock ticks, each with the time, and
answers with the :class:`Twist` to publish, if any; the vehicle's pilot
(:mod:`vehicle_agent.core.pilot`) drives it. The law it applies is the one its profile names
(:data:`LAWS`). A law asks for the speeds it wants; the robot's top speed holds them in the
pilot's limiter alone (:mod:`vehicle_agent.core.limits`), to the share of it a law that drives
as much as it faces its target allows (:attr:`Twist.top_share`). The browser vehicle page's
``control.js`` is a port of this module, checked against it on a grid
(``e2e/test_control_js.py``); the numbers both use live in :mod:`app.protocol.control`.

Coordinate conventions: image pixels have their origin at the top-left corner with y growing
downward; the turtlesim terrain has its origin at the bottom-left corner with y growing upward.
A goal pixel is therefore flipped vertically when mapped to the terrain: a face in the top half
of the frame is a target in the upper half of the terrain, i.e. the turtle looks "up" (θ > 0).
That is the fixed camera's geometry (the rotate and follow laws). A camera the vehicle carries
(the onboard law) turns with it: a goal pixel is a bearing, positive to the left as θ is
counter-clockwise, and the target's box height against its real height is a range.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

from app.protocol.angles import wrap_angle
from app.protocol.control import (
    HEADING_MEMORY_S,
    MIN_TARGET_DISTANCE_M,
    PROFILES,
    SPAWN_THETA,
    TERRAIN_CENTRE,
    WORLD_SIZE,
    Law,
    Profile,
)

__all__ = [
    "PROFILES",
    "SPAWN_THETA",
    "TERRAIN_CENTRE",
    "WORLD_SIZE",
    "LAWS",
    "ControlLaw",
    "Controller",
    "Goal",
    "Pose",
    "Profile",
    "Twist",
    "ZERO_TWIST",
    "angular_command",
    "follow_command",
    "follow_law",
    "onboard_law",
    "pixel_bearing",
    "pixel_to_terrain",
    "target_range",
    "rotate_law",
    "steering_error",
    "wall_clearance",
    "wrap_angle",
]


@dataclass(frozen=True)
class Pose:
    """Where the turtle is: terrain metres and heading in radians."""

    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Goal:
    """A target pixel of a ``w``×``h`` frame, as sent by the relay; ``box_h`` its box's height
    (pixels) and ``target_height_m`` the real height the box spans, when the relay sent them.

    ``heading`` is the vehicle's heading when the goal's frame was taken, or else when the goal
    arrived (the controller sets it): a bearing is relative to the heading the vehicle had then.
    ``drift`` is how fast the target itself turns about the vehicle (rad/s in the room's frame,
    positive counter-clockwise: 0 when not measured) and ``age`` how long ago its frame was
    taken (s); the controller sets both, and the onboard law leads the target by them.
    """

    x: float
    y: float
    w: int
    h: int
    seq: int | None = None
    frame: int | None = None
    box_h: float | None = None
    target_height_m: float | None = None
    heading: float | None = None
    drift: float = 0.0
    age: float = 0.0


@dataclass(frozen=True)
class Twist:
    """A velocity command; ``seq``/``frame`` name the goal it came from (None for a stop).

    ``top_share`` is the share of the robot's top speed ``linear_x`` may reach: a law that
    drives only as much as it faces its target says how much it does, and the pilot's limiter
    (:mod:`vehicle_agent.core.limits`), which alone knows the robot's top speed, clamps to that
    share of it. 1 for every other command.
    """

    linear_x: float
    angular_z: float
    seq: int | None = None
    frame: int | None = None
    top_share: float = 1.0

    @property
    def is_zero(self) -> bool:
        """True for the stop command."""
        return self.linear_x == 0.0 and self.angular_z == 0.0


ZERO_TWIST = Twist(0.0, 0.0)


def _clamp(value: float, low: float, high: float) -> float:
    return max(low, min(high, value))


def pixel_to_terrain(x: float, y: float, w: int, h: int) -> tuple[float, float]:
    """Map a goal pixel of a ``w``×``h`` frame to terrain metres (image y flipped)."""
    return x * TERRAIN_CENTRE / (w / 2), (h - y) * TERRAIN_CENTRE / (h / 2)


def steering_error(goal: Goal, pose: Pose) -> float | None:
    """Signed turn, in (−π, π], that makes the turtle face the goal; None when undefined."""
    tx, ty = pixel_to_terrain(goal.x, goal.y, goal.w, goal.h)
    return _heading_error(tx, ty, pose)


def _heading_error(tx: float, ty: float, pose: Pose) -> float | None:
    dx, dy = tx - pose.x, ty - pose.y
    # A non-finite goal or pose has no direction: never a command (NaN would pass every clamp).
    if (
        not all(map(math.isfinite, (dx, dy, pose.theta)))
        or math.hypot(dx, dy) < MIN_TARGET_DISTANCE_M
    ):
        return None
    return wrap_angle(math.atan2(dy, dx) - pose.theta)


def angular_command(error: float, profile: Profile) -> float:
    """The profile's angular velocity for a steering error."""
    if abs(error) < profile.deadband:
        return 0.0
    command = profile.gain * error
    return _clamp(command, -profile.max_angular, profile.max_angular)


def wall_clearance(pose: Pose, forward: bool) -> float:
    """Metres the turtle can travel straight ahead (or straight back) before a wall."""
    sign = 1.0 if forward else -1.0
    clearance = math.inf
    for position, component in (
        (pose.x, sign * math.cos(pose.theta)),
        (pose.y, sign * math.sin(pose.theta)),
    ):
        if component > 1e-12:
            clearance = min(clearance, (WORLD_SIZE - position) / component)
        elif component < -1e-12:
            clearance = min(clearance, -position / component)
    return max(0.0, clearance)


def follow_command(tx: float, ty: float, pose: Pose, profile: Profile) -> Twist:
    """The command that takes the turtle to ``profile.standoff_m`` from terrain point (``tx``,
    ``ty``): turn towards it, drive as much as it faces it, slow near walls (when the profile
    knows of them: a turtlesim's)."""
    margin = profile.wall_margin_m
    if profile.walls:
        # A target at the edge of the frame would lead the turtle into the wall; aim inside.
        tx = _clamp(tx, margin, WORLD_SIZE - margin)
        ty = _clamp(ty, margin, WORLD_SIZE - margin)
    error = _heading_error(tx, ty, pose)
    if error is None:
        return ZERO_TWIST
    angular = angular_command(error, profile)
    distance = math.hypot(tx - pose.x, ty - pose.y)
    # Only the part of the heading that points at the target is worth driving along; facing
    # away, the turtle turns first. The share holds for the robot's top speed too.
    facing = max(0.0, math.cos(error))
    linear = profile.linear_gain * (distance - profile.standoff_m) * facing
    if not profile.walls:
        return Twist(linear, angular, top_share=facing)
    # The speed allowed shrinks with the clearance ahead (behind, when backing off) and is zero
    # at the wall margin: the turtle never drives into a wall, and can always turn away.
    allowed = max(0.0, profile.wall_gain * (wall_clearance(pose, linear >= 0) - margin))
    return Twist(_clamp(linear, -allowed, allowed), angular, top_share=facing)


def rotate_law(goal: Goal, pose: Pose, profile: Profile) -> Twist:
    """The rotate law: turn in place to face the goal's terrain point."""
    error = steering_error(goal, pose)
    # No defined heading: hold still rather than keep the last turn going.
    return Twist(0.0, 0.0 if error is None else angular_command(error, profile))


def follow_law(goal: Goal, pose: Pose, profile: Profile) -> Twist:
    """The follow law: drive to the profile's standoff from the goal's terrain point."""
    tx, ty = pixel_to_terrain(goal.x, goal.y, goal.w, goal.h)
    # A non-finite goal or pose has no direction: hold still (NaN would pass every clamp).
    if not all(map(math.isfinite, (tx, ty, pose.x, pose.y, pose.theta))):
        return ZERO_TWIST
    return follow_command(tx, ty, pose, profile)


def _focal_px(w: float, hfov: float) -> float:
    """The focal length in pixels of a camera ``hfov`` radians across a frame ``w`` wide."""
    return (w / 2) / math.tan(hfov / 2)


def pixel_bearing(x: float, w: float, hfov: float) -> float:
    """The bearing (rad) of pixel column ``x`` of a frame ``w`` wide seen by a camera ``hfov``
    across, from the camera's axis: positive to the left, as θ counter-clockwise, so a target
    right of the image centre has a negative bearing."""
    return -math.atan((x - w / 2) / _focal_px(w, hfov))


def target_range(box_h: float, height_m: float, w: float, hfov: float) -> float:
    """The distance (m) at which something ``height_m`` high spans ``box_h`` pixels, seen by a
    camera ``hfov`` across a frame ``w`` wide (square pixels): ``f · H / h``."""
    return _focal_px(w, hfov) * height_m / box_h


def onboard_law(goal: Goal, pose: Pose, profile: Profile) -> Twist:
    """The onboard law: turn the target's bearing toward zero, and drive to the standoff from
    it as much as the vehicle faces it.

    The bearing is the goal pixel's, less how far the vehicle has turned since its frame was
    taken (or since the goal arrived, when the vehicle does not know when that was): what it
    turned while the frame was on its way and between goals keeps the command current. A target
    that moves round the vehicle (``goal.drift``) has moved on by its drift times the frame's
    age, and the vehicle turns at its drift besides: a turn in proportion to the bearing alone
    would trail it by the drift over the gain. The range comes from the box's height; without
    a box or a real height the vehicle only turns.
    """
    if profile.hfov <= 0:
        return ZERO_TWIST
    bearing = pixel_bearing(goal.x, goal.w, profile.hfov) + goal.drift * goal.age
    if goal.heading is not None:
        bearing = wrap_angle(bearing - wrap_angle(pose.theta - goal.heading))
    # A non-finite goal or pose has no direction: hold still (NaN would pass every clamp).
    if not math.isfinite(bearing):
        return ZERO_TWIST
    angular = angular_command(bearing, profile)
    if goal.drift != 0.0:
        angular = _clamp(angular + goal.drift, -profile.max_angular, profile.max_angular)
    if goal.box_h is None or goal.target_height_m is None:
        return Twist(0.0, angular)
    distance = target_range(goal.box_h, goal.target_height_m, goal.w, profile.hfov)
    # Full speed facing the target, none at ``slow_bearing`` off it: turn first, then drive.
    # The share holds for the robot's top speed too.
    facing = max(0.0, 1.0 - abs(bearing) / profile.slow_bearing)
    linear = profile.linear_gain * (distance - profile.standoff_m) * facing
    return Twist(linear, angular, top_share=facing)


# A control law: the command that steers from ``pose`` toward ``goal``, at the speeds the law
# wants (the pilot's limiter holds them to the robot's); its ``seq`` and ``frame`` are the
# controller's to set.
ControlLaw = Callable[[Goal, Pose, Profile], Twist]
# The laws a profile can name (``Profile.law``); a new law is a function and an entry here (and
# its twin in control.js).
LAWS: dict[Law, ControlLaw] = {"rotate": rotate_law, "follow": follow_law, "onboard": onboard_law}


class Controller:
    """Turns goals into Twists with one profile and the control law it names.

    Call :meth:`goal` for each goal, :meth:`pose` for each pose update and :meth:`tick`
    regularly (every few tens of milliseconds), each with the time now (seconds, one clock);
    each returns the Twist to publish now, if any.

    Closed-loop profiles (``on_pose``) answer a new goal at once, as soon as the command-rate
    cap (``min_interval_s`` since the previous Twist) allows, and between goals answer pose
    updates every ``period_s``. The thesis profile publishes on its own clock. After a goal
    timeout or :meth:`stop` exactly one zero Twist is returned, then nothing until the next
    goal. The searching profiles (follow, onboard) stop driving and turn in place when no goal
    came for ``search_after_s``, toward the side the target was last seen on, until a goal
    comes back (:attr:`search_since` says since when) or the goal timeout stops the search.
    ``law`` replaces the profile's (:data:`LAWS`).
    """

    def __init__(self, profile: Profile, law: ControlLaw | None = None) -> None:
        self.profile = profile
        self.law = LAWS[profile.law] if law is None else law
        self._goal: Goal | None = None
        self._goal_at = 0.0
        # The latest goal has not produced a Twist yet.
        self._unanswered = False
        # The side the target was last seen on (+1 left, −1 right): where a search turns first.
        self._last_side = 1.0
        self._pose: Pose | None = None
        # The headings of the last HEADING_MEMORY_S, oldest first: (time, theta).
        self._headings: deque[tuple[float, float]] = deque()
        self._last_publish: float | None = None
        # When the search under way began (its first search Twist), None when not searching.
        self._search_since: float | None = None
        # When the current goal's frame was taken (or it arrived, when that is not known).
        self._captured = 0.0
        # The target's recent sightings, oldest first: (when its frame was taken, its bearing
        # in the room's frame, unwrapped), for its drift (Profile.drift_window_s).
        self._sightings: deque[tuple[float, float]] = deque()

    @property
    def search_since(self) -> float | None:
        """When the search under way began (its first Twist went out), None when none is."""
        return self._search_since

    @property
    def last_side(self) -> float:
        """The side the target was last seen on, +1 left or −1 right: where a search turns."""
        return self._last_side

    @property
    def active(self) -> bool:
        """True while goals are arriving (the turtle is being piloted)."""
        return self._goal is not None

    def searching(self, now: float) -> bool:
        """True while the follow profile has lost its target and turns to find it."""
        return self._goal is not None and self._lost(now)

    def goal(self, goal: Goal, now: float, captured_at: float | None = None) -> Twist | None:
        """Take a new goal and answer it now when the profile's timing allows; it ends a
        search. ``captured_at``: when its frame was taken, on ``now``'s clock, if known."""
        captured = now if captured_at is None else captured_at
        heading = self._heading_at(captured)
        self._goal = replace(goal, heading=heading, drift=self._drift(goal, heading, captured))
        self._captured = captured
        self._goal_at = now
        self._unanswered = True
        self._search_since = None
        return self._due(now)

    def pose(self, pose: Pose, now: float) -> Twist | None:
        """Take a pose update; closed-loop profiles answer with a Twist when one is due."""
        self._pose = pose
        self._headings.append((now, pose.theta))
        while self._headings[0][0] < now - HEADING_MEMORY_S:
            self._headings.popleft()
        timed_out = self._check_timeout(now)
        if timed_out is not None:
            return timed_out
        return self._due(now) if self.profile.on_pose else None

    def tick(self, now: float) -> Twist | None:
        """Check the goal timeout and, for the thesis profile, the publishing period."""
        timed_out = self._check_timeout(now)
        if timed_out is not None:
            return timed_out
        return None if self.profile.on_pose else self._due(now)

    def stop(self) -> Twist | None:
        """Piloting stopped or the relay left: one zero Twist if the turtle was being driven."""
        if self._goal is None:
            return None
        self._goal = None
        self._unanswered = False
        self._last_publish = None
        self._search_since = None
        self._sightings.clear()
        return ZERO_TWIST

    def _heading_at(self, t: float) -> float | None:
        """The vehicle's heading at ``t``: the last pose's at or before it (the oldest one
        remembered for an earlier ``t``), None before any pose."""
        if not self._headings:
            return None
        heading = self._headings[0][1]
        for at, theta in self._headings:
            if at > t:
                break
            heading = theta
        return heading

    def _drift(self, goal: Goal, heading: float | None, captured: float) -> float:
        """How fast the target turns about the vehicle (rad/s, room frame), from its sightings
        of the last ``drift_window_s`` once they span half of it; 0 before, and when the profile
        does not measure it. A sighting that moved faster than the vehicle can turn is a jump
        (another target, a detection astray), not a walk: the measure starts again from it."""
        profile = self.profile
        if profile.drift_window_s <= 0 or profile.hfov <= 0 or heading is None:
            return 0.0
        seen = heading + pixel_bearing(goal.x, goal.w, profile.hfov)
        if not math.isfinite(seen):
            self._sightings.clear()
            return 0.0
        sightings = self._sightings
        if sightings:
            last_at, last = sightings[-1]
            seen = last + wrap_angle(seen - last)
            if abs(seen - last) > profile.max_angular * max(0.0, captured - last_at):
                sightings.clear()
        # A frame seen before (or an older one) adds nothing to the measure.
        if not sightings or captured > sightings[-1][0]:
            sightings.append((captured, seen))
        while sightings[0][0] < captured - profile.drift_window_s:
            sightings.popleft()
        (first_at, first), (last_at, last) = sightings[0], sightings[-1]
        span = last_at - first_at
        return 0.0 if span < profile.drift_window_s / 2 else (last - first) / span

    def _lost(self, now: float) -> bool:
        return now - self._goal_at > self.profile.search_after_s

    def until_timeout(self, now: float) -> float | None:
        """Seconds until the goal timeout stops the turtle (0 when due), None with no goal.

        A caller that ticks on a coarse period wakes up at this moment too, so the stop goes
        out on time rather than up to a period late.
        """
        if self._goal is None:
            return None
        return max(0.0, self._goal_at + self.profile.goal_timeout_s - now)

    def _check_timeout(self, now: float) -> Twist | None:
        if self._goal is not None and now - self._goal_at >= self.profile.goal_timeout_s:
            return self.stop()
        return None

    def _due(self, now: float) -> Twist | None:
        goal, pose = self._goal, self._pose
        if goal is None or pose is None:
            return None
        last = self._last_publish
        profile = self.profile
        if profile.on_pose:
            gap = profile.min_interval_s if self._unanswered else profile.period_s
            if last is not None and now - last < gap:
                return None
            self._last_publish = now
        else:
            if last is not None and now - last < profile.period_s:
                return None
            # The clock-driven profile keeps a fixed cadence (like the thesis's setInterval)
            # instead of drifting by the tick granularity; after a pause it starts a new grid.
            if last is not None and now - last < 2 * profile.period_s:
                self._last_publish = last + profile.period_s
            else:
                self._last_publish = now
        answers_goal = self._unanswered
        self._unanswered = False
        if self._lost(now):
            if self._search_since is None:
                self._search_since = now
            return Twist(0.0, self._last_side * profile.search_angular)
        command = self.law(replace(goal, age=now - self._captured), pose, profile)
        # Where the goal put the target, not where the turns since have left the estimate: a
        # vehicle that turned past a target that left by the right must still search right.
        if answers_goal and command.angular_z != 0.0:
            self._last_side = 1.0 if command.angular_z > 0 else -1.0
        return replace(command, seq=goal.seq, frame=goal.frame)
