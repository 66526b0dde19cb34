"""The simulated differential-drive robot, its walled room and the camera it carries.

Plain synchronous code, time injected, as :mod:`app.turtlesim`: :mod:`.room` is the layout (the
walls and the billboards, one of them walking), :mod:`.robot` the kinematics, :mod:`.sim` both
stepped together, :mod:`.camera` the pinhole view from the robot, :mod:`.messages` what it
publishes. ``docs/simulated-room.md`` describes the room.
"""
