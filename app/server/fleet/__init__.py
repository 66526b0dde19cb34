"""Scaling out on Redis: signaling across instances (:mod:`.bus`), the relay pool (:mod:`.pool`)
and the ``/fleet`` page (:mod:`.page`). Key names and timings shared by all three live in
:mod:`.keys`."""
