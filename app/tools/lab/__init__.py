"""The field lab: NATs, TURN, loss, delay, caps and outages built from network namespaces."""

from app.tools.lab.conditions import CONDITIONS, Condition, condition
from app.tools.lab.lab import Lab, Site

__all__ = ["CONDITIONS", "Condition", "Lab", "Site", "condition"]
