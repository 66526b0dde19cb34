"""The server: app factory, settings, pages, the WebSocket adapter, routes and ``serve``."""
