"""Tools that drive Chromium or child processes: relay service, demo, parity, bench, field lab."""
