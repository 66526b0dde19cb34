"""The web server: app factory, settings, pages, WebSocket adapters and HTTP routes, and
the fleet layer on Redis (:mod:`app.server.fleet`)."""
