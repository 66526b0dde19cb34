"""``autopilot bench``: reproducible measurements of the running system, written up as a report."""
