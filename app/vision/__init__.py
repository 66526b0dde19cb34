"""The vision side: the operations spec both languages read, and the Python reference pipeline."""
