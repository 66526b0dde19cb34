"""``autopilot bench --fleet``'s signaling script on a real Redis and two real instances: every
relayed message arrives, none is refused (correctness only; the figures belong to the bench)."""

from __future__ import annotations

from pathlib import Path

from app.tools.bench.fleet import CANDIDATES, bench_signaling, serve_instance, write


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


def test_the_report_shows_both_arrival_rates(tmp_path: Path) -> None:
    def signaling(rate: float, p99: float) -> dict[str, object]:
        latencies = [1.0, 2.0, p99]
        return {
            "rooms": 3,
            "peers": 9,
            "arrival_rooms_per_s": rate,
            "messages": 3,
            "latency_ms_p50": 2.0,
            "latency_ms_p99": p99,
            "errors": 0,
            "lost": 0,
            "_latencies": latencies,
        }

    obj = {
        "signaling": signaling(10.0, 4.5),
        "signaling_burst": signaling(40.0, 38.0),
        "relay_density": {
            "rooms_sustained": 1,
            "min_goals_per_s": 15.0,
            "fps": 30,
            "cpus": 2,
            "steps": [
                {
                    "rooms": 1,
                    "started": True,
                    "per_room": {"density-1": {"goals_per_s": 29.5, "ms_per_snapshot": 10.1}},
                    "cores": {"relay": 0.4, "agents": 0.3, "server": 0.1, "rest": 0.5},
                    "relay_cores_per_room": 0.4,
                },
                {
                    "rooms": 2,
                    "started": True,
                    "per_room": {
                        "density-1": {"goals_per_s": 12.0, "ms_per_snapshot": 30.0},
                        "density-2": {"goals_per_s": 11.0, "ms_per_snapshot": 31.0},
                    },
                    "cores": {"relay": 0.6, "agents": 0.6, "server": 0.1, "rest": 0.7},
                    "relay_cores_per_room": 0.3,
                },
            ],
        },
        "failover": {"instance_peers_told_s": 2.9, "pool_takeover_s": 6.1},
        "notes": {},
    }
    write(tmp_path, obj)
    report = (tmp_path / "fleet.md").read_text()
    assert "(steady arrival)" in report and "arriving at 10 rooms/s" in report
    assert "(burst)" in report and "arriving at 40 rooms/s" in report and "p99 38.0 ms" in report
    assert "| 1 | 29.5 (10.1) | 0.4, 0.3, 0.1, 0.5 | 0.4 |" in report
    # The relay's share per room is taken only where every room kept its goal rate.
    assert "costs the relay pool (its Chromium included) 0.4 cores" in report
    assert "would hold about 5 rooms on 2 cores" in report
    assert "_latencies" not in (tmp_path / "fleet.json").read_text()
    assert (tmp_path / "fleet-latency.png").stat().st_size > 0
