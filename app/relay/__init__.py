"""The relay as a process: its page in headless Chromium, kept running for one room or a pool.

The relay's work (video analysis, goals, forwarding) happens in its page,
``app/static/js/pages/relay.js``; this package starts and keeps that page, reads its status and
exports its metrics. Dependencies point one way:

- :mod:`app.relay.page`: the relay page's address, the server check, closing a page, and the
  shared error -- what both ways of running it need;
- :mod:`app.relay.service`: one page for one room (``autopilot relay``);
- :mod:`app.relay.pool`: one browser serving every room that needs a relay, on Redis
  (``autopilot relay --pool``);
- :mod:`app.relay.metrics`: the Prometheus series read from the pages;
- :mod:`app.relay.cli`: the command's options and its choice between service and pool.
"""
