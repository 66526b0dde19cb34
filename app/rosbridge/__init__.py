"""The rosbridge v2 protocol without I/O: sessions, subscriptions and rosapi, over any simulated
robot (a :class:`~app.rosbridge.protocol.Hub`); the server's ``/rosbridge`` moves the frames."""
