"""The role pages: each embeds the configuration it needs to run from its URL alone."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from html.parser import HTMLParser
from typing import Any

import httpx
import pytest

from app.server.config import IceServer, Settings
from app.server.serve import RunningServer

ROLES = ("vehicle", "relay", "client")


def embedded_config(html: str) -> dict[str, Any]:
    match = re.search(r'<script type="application/json" id="config">(.*?)</script>', html, re.S)
    assert match, "page has no embedded config"
    config: dict[str, Any] = json.loads(match.group(1))
    return config


class Buttons(HTMLParser):
    """Collects the visible text of every <button>."""

    def __init__(self) -> None:
        super().__init__()
        self.labels: list[str] = []
        self._inside = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "button":
            self._inside = True
            self.labels.append("")

    def handle_endtag(self, tag: str) -> None:
        if tag == "button":
            self._inside = False

    def handle_data(self, data: str) -> None:
        if self._inside:
            self.labels[-1] += data.strip()


@pytest.fixture
def turn_server(
    start_server: Callable[[Settings], RunningServer], settings: Settings
) -> RunningServer:
    ice = [IceServer(urls=["turn:turn.example:3478"], username="u", credential="c")]
    return start_server(settings.model_copy(update={"ice_servers": ice}))


def test_index_links_the_three_pages_for_the_room(server: RunningServer) -> None:
    html = httpx.get(f"{server.url}/?room=lab").text
    for role in ROLES:
        assert f'href="/{role}?room=lab' in html


@pytest.mark.parametrize("role", ROLES)
def test_defaults_no_ice_servers_and_this_servers_rosbridge(
    server: RunningServer, role: str
) -> None:
    response = httpx.get(f"{server.url}/{role}")
    assert response.status_code == 200
    config = embedded_config(response.text)
    assert config["role"] == role
    assert config["iceServers"] == []  # nothing leaves the machine unless configured
    assert config["wsPath"] == "/ws"
    assert config["room"] == "default"
    assert config["auto"] is False
    assert config["profile"] == "default"
    assert config["rosbridge"] == server.url.replace("http://", "ws://") + "/rosbridge"
    assert config["ros"] == "1"


def test_query_sets_room_name_auto_profile_and_rosbridge(server: RunningServer) -> None:
    query = "room=r1&name=v1&auto=1&profile=thesis&rosbridge=ws://robot:9090&ros=2"
    config = embedded_config(httpx.get(f"{server.url}/vehicle?{query}").text)
    assert (config["room"], config["name"], config["auto"]) == ("r1", "v1", True)
    assert config["profile"] == "thesis"
    assert (config["rosbridge"], config["ros"]) == ("ws://robot:9090", "2")


def test_an_unknown_profile_falls_back_to_default(server: RunningServer) -> None:
    config = embedded_config(httpx.get(f"{server.url}/relay?profile=turbo").text)
    assert config["profile"] == "default"


def test_ice_servers_come_from_settings(turn_server: RunningServer) -> None:
    config = embedded_config(httpx.get(f"{turn_server.url}/client").text)
    assert config["iceServers"] == [
        {"urls": ["turn:turn.example:3478"], "username": "u", "credential": "c"}
    ]


def test_query_text_cannot_break_out_of_the_config_script(server: RunningServer) -> None:
    evil = "</script><script>alert(1)</script>"
    html = httpx.get(f"{server.url}/client", params={"room": evil}).text
    assert "<script>alert(1)" not in html
    assert embedded_config(html)["room"] == evil


def test_client_has_exactly_the_thesis_buttons_and_a_labelled_operation_list(
    server: RunningServer,
) -> None:
    html = httpx.get(f"{server.url}/client").text
    parser = Buttons()
    parser.feed(html)
    assert sorted(parser.labels) == sorted(
        ["Connect", "Join Room", "Leave Room", "Set Operation", "Start Piloting", "Stop Piloting"]
    )
    assert re.search(r'<label for="operation">Select Operation</label>', html)
    assert re.search(r'<select id="operation"', html)
    assert "Current State:" in html


@pytest.mark.parametrize("role", ("vehicle", "relay"))
def test_vehicle_and_relay_have_the_room_buttons(server: RunningServer, role: str) -> None:
    parser = Buttons()
    parser.feed(httpx.get(f"{server.url}/{role}").text)
    assert parser.labels == ["Connect", "Join Room", "Leave Room"]


def test_vehicle_page_loads_the_vendored_roslib_not_a_cdn(server: RunningServer) -> None:
    html = httpx.get(f"{server.url}/vehicle").text
    assert '<script src="/static/vendor/roslib.min.js"></script>' in html
    assert not re.search(r'src="(https?:)?//', html)
    assert httpx.get(f"{server.url}/static/vendor/roslib.min.js").status_code == 200
