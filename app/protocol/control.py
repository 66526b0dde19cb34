"""The control law's numbers: terrain geometry and the vehicle profiles.

Written once here and read by both vehicles: the Python agent's law
(:mod:`vehicle_agent.core.control`) imports them, and the browser vehicle page's ``control.js``
receives them through its embedded config (:func:`control_config`), so neither re-types a gain,
a distance or a profile name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

from app.protocol.relay_profiles import DEFAULT_PROFILE
from app.protocol.relay_profiles import Profile as RelayProfile
from app.protocol.robot import Robot
from app.protocol.turtlesim_world import TERRAIN_CENTRE, WORLD_SIZE

# Below this distance the direction to the target is meaningless (the thesis's turtle sits at
# the terrain centre, which is where a goal in the middle of the frame lands).
MIN_TARGET_DISTANCE_M = 0.05
# The spawn step of the thesis's vehicle (section 5.7.6): turtle1 first turns to face "up".
SPAWN_THETA = math.pi / 2

# How far back a controller remembers the vehicle's heading, to take a goal's bearing from the
# heading its frame was taken at: longer than a fresh goal takes from its camera to the vehicle.
HEADING_MEMORY_S = 1.0
# How many of its camera's latest frames a vehicle remembers the capture time of, for the goals
# found in them: more than a second of a 30 fps camera, and goals older than that are stale.
KEPT_FRAMES = 120

Law = Literal["rotate", "follow", "onboard"]

# The operator's console (manual override). A vehicle that was moving on a drive command and has
# had none for DEADMAN_S stops; a held key or stick resends its command every DRIVE_REPEAT_S, so a
# live operator never trips it, and a lost or stuck client stops the vehicle within 0.3 s.
DEADMAN_S = 0.3
DRIVE_REPEAT_S = 0.1
# A vehicle's pilot looks at its clock this often (goal timeout, the clock-driven profile's
# period, the dead-man), and sooner when a stop falls due before.
TICK_S = 0.05


@dataclass(frozen=True)
class Profile:
    """How a vehicle turns goals into Twists: timing, the law, and the law's numbers.

    Times are seconds, distances metres, angles radians. A field that does not apply to a law
    keeps its neutral default (``math.inf`` for "never", 0 for "none").
    """

    name: str
    # "rotate": turn in place to face the target; "follow": also drive to a standoff from it;
    # "onboard": the camera turns with the vehicle, so steer the target's bearing to zero and
    # its range (from its box's height) to the standoff.
    law: Law
    # Minimum time between two Twists computed on pose updates (or on the clock, see on_pose).
    period_s: float
    # True: closed loop, a Twist on a new goal and on pose updates; False: on the clock alone.
    on_pose: bool
    # The command-rate cap: a Twist answering a new goal waits at least this long after the
    # previous Twist, so a burst of goals cannot flood cmd_vel.
    min_interval_s: float
    gain: float
    max_angular: float
    deadband: float
    # No goal for this long: the vehicle stops (one zero Twist).
    goal_timeout_s: float
    # The relay profile (snapshot pacing and detector parameters) this vehicle profile pairs with.
    relay_profile: RelayProfile
    # The operation (app/vision/operations.json) a relay started for this profile runs until a
    # client sets another; None: the spec's default.
    operation: str | None = None
    # --- follow only -------------------------------------------------------------------------
    # Forward speed per metre beyond the standoff (1/s); no profile caps it: the robot's top
    # speed does, in the pilot's limiter.
    linear_gain: float = 0.0
    # The distance kept from the target point.
    standoff_m: float = 0.0
    # Clearance from a wall at which forward (or backward) travel towards it has stopped; the
    # target point itself is kept this far inside the world.
    wall_margin_m: float = 0.0
    # Speed allowed per metre of clearance beyond the margin (1/s): the vehicle slows near walls.
    wall_gain: float = 0.0
    # Whether the walls are known: turtlesim's terrain has them; any other robot's surroundings
    # are not the terrain, so the follow law neither aims inside it nor slows near its walls.
    walls: bool = True
    # No goal for this long: the target counts as lost and the vehicle turns in place to search,
    # toward the side it was last seen on, until the goal timeout stops it.
    search_after_s: float = math.inf
    search_angular: float = 0.0
    # --- onboard only ------------------------------------------------------------------------
    # The camera's horizontal field of view (rad): the robot's (0: no camera described).
    hfov: float = 0.0
    # The bearing (rad) at which the forward speed has fallen to zero: the vehicle drives while
    # it faces the target and turns first when it does not.
    slow_bearing: float = math.inf
    # Over how long (s) the target's own turn about the vehicle (its bearing in the room's
    # frame, per second) is measured from its sightings: the vehicle turns with it as well as
    # toward it, so that a target walking round it is not trailed by that rate over the gain
    # (0: the target's motion is not measured).
    drift_window_s: float = 0.0
    # --- manual override ---------------------------------------------------------------------
    # An operator's full key or stick deflection (a drive command of 1) is this speed.
    manual_linear: float = 1.5
    manual_angular: float = 2.0


_DEFAULT = Profile(
    name="default",
    law="rotate",
    period_s=0.05,
    on_pose=True,
    min_interval_s=0.02,
    gain=6.0,
    max_angular=4.0,
    deadband=0.01,
    # A lost link must stop the turtle within 0.75 s of the last goal; the stop is timed to
    # the millisecond, and 50 ms to spare cover an event loop that wakes up late.
    goal_timeout_s=0.7,
    relay_profile="default",
)

PROFILES: dict[str, Profile] = {
    "default": _DEFAULT,
    # The thesis publishes the latest goal every 1100 ms; turtlesim runs a command for 1 s, so
    # angular.z = e turns the turtle by e.
    "thesis": Profile(
        name="thesis",
        law="rotate",
        period_s=1.1,
        on_pose=False,
        min_interval_s=1.1,
        gain=1.0,
        max_angular=math.inf,
        deadband=0.0,
        goal_timeout_s=2.5,
        relay_profile="thesis",
    ),
    # Drive towards the target's terrain point and hold a standoff from it, paced and turning
    # as the default does.
    "follow": replace(
        _DEFAULT,
        name="follow",
        law="follow",
        max_angular=5.0,
        # Searching stops after this long without any goal: the relay may be gone.
        goal_timeout_s=10.0,
        linear_gain=3.0,
        standoff_m=1.0,
        wall_margin_m=0.5,
        wall_gain=1.0,
        search_after_s=1.0,
        search_angular=1.0,
    ),
    # A camera carried by the vehicle (a robot's own): steer the target's bearing to zero and
    # hold a standoff from it, its range read from its box's height. A target lost for a moment
    # is searched for toward the side it left by, a turn and a half at most, then the vehicle
    # stops.
    "onboard": replace(
        _DEFAULT,
        name="onboard",
        law="onboard",
        gain=4.0,
        max_angular=2.5,
        deadband=0.02,
        # A walker at 0.6 m/s is trailed 0.6 / 2.5 m beyond the standoff.
        linear_gain=2.5,
        standoff_m=1.2,
        slow_bearing=0.45,
        # A few goals' worth: the rate is still the walker's of the moment.
        drift_window_s=0.5,
        search_after_s=0.3,
        search_angular=1.6,
        goal_timeout_s=0.3 + 3 * math.pi / 1.6,
        # The detector the onboard bench measures following the walker better (docs/performance.md,
        # "Which detector the onboard profile uses").
        operation="face_small",
    ),
}
__all__ = [
    "DEADMAN_S",
    "HEADING_MEMORY_S",
    "KEPT_FRAMES",
    "DEFAULT_PROFILE",
    "DRIVE_REPEAT_S",
    "PROFILES",
    "TERRAIN_CENTRE",
    "TICK_S",
    "WORLD_SIZE",
    "ControlConfig",
    "Profile",
    "control_config",
    "for_robot",
    "with_standoff",
]


def with_standoff(profile: Profile, standoff_m: float | None) -> Profile:
    """``profile`` with another standoff distance (None keeps the profile's own)."""
    if standoff_m is None:
        return profile
    if not math.isfinite(standoff_m) or standoff_m < 0:
        raise ValueError(f"standoff must be a finite distance >= 0 m, not {standoff_m}")
    return replace(profile, standoff_m=standoff_m)


def for_robot(profile: Profile, robot: Robot) -> Profile:
    """``profile`` fitted to ``robot``: an operator's full deflection is at most the robot's top
    speed (so the stick spans the robot's range rather than saturating early), the follow law
    knows of walls on a turtlesim only, and the onboard law sees through the robot's camera
    (its field of view turns a pixel into a bearing; no camera, no bearing). Every command is
    held to the limits by the pilot's limiter, the only place they clamp one."""
    limits = robot.limits
    camera = robot.camera
    return replace(
        profile,
        manual_linear=min(profile.manual_linear, limits.max_linear),
        manual_angular=min(profile.manual_angular, limits.max_angular),
        walls=robot.turtlesim,
        hfov=0.0 if camera is None else math.radians(camera.hfov_deg),
    )


@dataclass(frozen=True)
class ControlConfig:
    """Everything ``control.js`` and ``manual.js`` need, for a page's embedded config."""

    world_size: float
    terrain_centre: float
    min_target_distance_m: float
    spawn_theta: float
    deadman_s: float
    drive_repeat_s: float
    tick_s: float
    heading_memory_s: float
    kept_frames: int
    profiles: dict[str, Profile]


def control_config(profiles: dict[str, Profile] | None = None) -> ControlConfig:
    """The control law's numbers with ``profiles`` (default: :data:`PROFILES`)."""
    return ControlConfig(
        world_size=WORLD_SIZE,
        terrain_centre=TERRAIN_CENTRE,
        min_target_distance_m=MIN_TARGET_DISTANCE_M,
        spawn_theta=SPAWN_THETA,
        deadman_s=DEADMAN_S,
        drive_repeat_s=DRIVE_REPEAT_S,
        tick_s=TICK_S,
        heading_memory_s=HEADING_MEMORY_S,
        kept_frames=KEPT_FRAMES,
        profiles=PROFILES if profiles is None else profiles,
    )
