"""The web server: app factory, settings, pages, WebSocket adapters and HTTP routes."""
