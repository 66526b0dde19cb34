"""The simulated turtle (ROS turtlesim behaviour) and its rosbridge v2 endpoint."""

from app.turtlesim.sim import Pen, Pose, Stroke, TurtleSim

__all__ = ["Pen", "Pose", "Stroke", "TurtleSim"]
