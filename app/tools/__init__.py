"""Tools around the server: relay service, demo, parity, bench, token minting."""
