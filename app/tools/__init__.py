"""Tools that drive the system from outside: browser, relay service and pool, demo, bench."""
