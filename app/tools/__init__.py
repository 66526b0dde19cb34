"""Tools built on the system: browsers, the relay service, demo, parity, bench and the field lab."""
