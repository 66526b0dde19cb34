"""``autopilot bench --fleet``'s signaling script on a real Redis and two real instances: every
relayed message arrives, none is refused (correctness only; the figures belong to the bench)."""

from __future__ import annotations

from pathlib import Path

from app.tools.bench.fleet import CANDIDATES, bench_signaling, serve_instance


async def test_the_scripted_rooms_get_every_message_across_two_instances(
    redis_url: str, tmp_path: Path
) -> None:
    with (
        serve_instance(redis_url, tmp_path) as (a, _),
        serve_instance(redis_url, tmp_path) as (
            b,
            _,
        ),
    ):
        result = await bench_signaling([a, b], rooms=3)
    # Per room: vehicle and client each trade an offer, an answer and CANDIDATES candidates
    # both ways with the relay, then the client's start and stop.
    per_room = 2 * (2 + 2 * CANDIDATES) + 2
    assert (result["errors"], result["lost"]) == (0, 0), result["_error_samples"]
    assert result["messages"] == 3 * per_room
    assert len(result["_latencies"]) == result["messages"]
