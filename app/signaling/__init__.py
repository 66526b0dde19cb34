"""Signaling server (DESIGN §2): typed messages, a sans-I/O hub of rooms, and the /ws route."""
