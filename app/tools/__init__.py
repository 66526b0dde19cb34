"""Tools that drive Chromium or child processes: relay service and pool, demo, parity, bench,
field lab."""
