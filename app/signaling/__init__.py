"""Signaling: the sans-I/O hub of rooms (docs/architecture.md, "Signaling protocol")."""
