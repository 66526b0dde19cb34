"""The Python vehicle: streams video to the relay with aiortc and drives a turtle from goals."""
