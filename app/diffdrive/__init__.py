"""The simulated differential-drive robot, its walled arena and the camera it carries.

Plain synchronous code, time injected, as :mod:`app.turtlesim`: :mod:`.arena` is the layout (the
walls and the billboards, one of them walking), :mod:`.robot` the kinematics, :mod:`.sim` both
stepped together, :mod:`.camera` the pinhole view from the robot, :mod:`.messages` what it
publishes. ``docs/simulated-arena.md`` describes the arena.
"""
