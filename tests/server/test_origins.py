"""The Origin allow-list: own pages and listed sites in, other sites out, tools to their token."""

from __future__ import annotations

import pytest

from app.server.origins import Verdict, judge, normalise


@pytest.mark.parametrize(
    ("origin", "host", "verdict"),
    [
        ("http://127.0.0.1:8000", "127.0.0.1:8000", Verdict.OWN),
        ("https://10.203.0.1:8443", "10.203.0.1:8443", Verdict.OWN),
        ("https://Robot.Example", "robot.example", Verdict.OWN),
        ("https://robot.example", "robot.example:443", Verdict.OWN),
        ("http://[::1]:8000", "[::1]:8000", Verdict.OWN),
        (None, "127.0.0.1:8000", Verdict.ABSENT),
        ("http://evil.example", "127.0.0.1:8000", Verdict.FOREIGN),
        # Same host, other port: another server on the machine, not this one.
        ("http://127.0.0.1:9000", "127.0.0.1:8000", Verdict.FOREIGN),
        ("http://127.0.0.1:8000.evil.example", "127.0.0.1:8000", Verdict.FOREIGN),
        ("null", "127.0.0.1:8000", Verdict.FOREIGN),
        ("file://", "127.0.0.1:8000", Verdict.FOREIGN),
        ("", "127.0.0.1:8000", Verdict.FOREIGN),
        ("http://127.0.0.1:8000", None, Verdict.FOREIGN),
    ],
)
def test_verdicts(origin: str | None, host: str | None, verdict: Verdict) -> None:
    assert judge(origin, host) is verdict
    assert judge(origin, host).admitted is (verdict is not Verdict.FOREIGN)


def test_listed_origins_are_admitted_in_any_spelling() -> None:
    allowed = ["https://Ops.Example:443", "http://console.example:8080"]
    assert judge("https://ops.example", "server:8443", allowed) is Verdict.LISTED
    assert judge("http://console.example:8080", "server:8443", allowed) is Verdict.LISTED
    assert judge("http://console.example", "server:8443", allowed) is Verdict.FOREIGN
    assert judge("https://ops.example.evil", "server:8443", allowed) is Verdict.FOREIGN


@pytest.mark.parametrize("bad", ["ops.example", "ftp://ops.example", "https://ops.example/path"])
def test_an_allow_list_entry_that_is_not_an_origin_is_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="origin"):
        normalise(bad)
