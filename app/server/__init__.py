"""The server: app factory, configuration, pages, WebSocket adapter and the fleet layer."""
