"""The role pages: each embeds the configuration it needs to run from its URL alone."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from html.parser import HTMLParser
from typing import Any

import httpx
import pytest
from pydantic import SecretStr

from app.protocol.control import PROFILES, TERRAIN_CENTRE, WORLD_SIZE
from app.protocol.page import to_json
from app.protocol.ros import ROS_CONFIG
from app.resources import OPERATIONS_SPEC
from app.server.config import IceServer, Settings
from app.server.serve import RunningServer
from app.vision import spec

ROLES = ("vehicle", "relay", "client")
TURN_SECRET = "shared-with-coturn"


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
    turn = {
        "ice_servers": [IceServer(urls=["stun:stun.example:3478"])],
        "turn_urls": ["turn:turn.example:3478"],
        "turn_secret": SecretStr(TURN_SECRET),
    }
    return start_server(settings.model_copy(update=turn))


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
    assert "iceServers" not in config  # ICE comes with the login reply
    assert config["wsPath"] == "/ws"
    assert config["room"] == "default"
    assert config["auto"] is False
    assert config["profile"] == "default"
    assert config["rosbridge"] == server.url.replace("http://", "ws://") + "/rosbridge"
    # The page learns the robot's flavour from rosapi unless told; the type table comes along.
    assert config["ros"] == "auto"
    assert config["rosTypes"] == to_json(ROS_CONFIG)


def test_query_sets_room_name_auto_profile_and_rosbridge(server: RunningServer) -> None:
    query = "room=r1&name=v1&auto=1&profile=thesis&rosbridge=ws://robot:9090&ros=2"
    config = embedded_config(httpx.get(f"{server.url}/vehicle?{query}").text)
    assert (config["room"], config["name"], config["auto"]) == ("r1", "v1", True)
    assert config["profile"] == "thesis"
    assert (config["rosbridge"], config["ros"]) == ("ws://robot:9090", "2")


def test_an_unknown_ros_setting_falls_back_to_auto(server: RunningServer) -> None:
    config = embedded_config(httpx.get(f"{server.url}/vehicle?ros=3").text)
    assert config["ros"] == "auto"
    config = embedded_config(httpx.get(f"{server.url}/vehicle?ros=jazzy").text)
    assert config["ros"] == "jazzy"


def test_an_unknown_profile_falls_back_to_default(server: RunningServer) -> None:
    config = embedded_config(httpx.get(f"{server.url}/relay?profile=turbo").text)
    assert config["profile"] == "default"


@pytest.mark.parametrize("role", ROLES)
def test_control_law_numbers_reach_every_page_from_python(server: RunningServer, role: str) -> None:
    config = embedded_config(httpx.get(f"{server.url}/{role}").text)
    control = config["control"]
    assert control["worldSize"] == WORLD_SIZE and control["terrainCentre"] == TERRAIN_CENTRE
    assert sorted(control["profiles"]) == sorted(PROFILES)
    follow = control["profiles"]["follow"]
    python = PROFILES["follow"]
    assert follow["standoffM"] == python.standoff_m
    assert follow["wallMarginM"] == python.wall_margin_m
    assert follow["searchAfterS"] == python.search_after_s
    assert follow["linearGain"] == python.linear_gain
    # JSON has no infinity: "no limit" travels as null.
    assert control["profiles"]["thesis"]["maxAngular"] is None
    assert control["profiles"]["default"]["searchAfterS"] is None


def test_follow_on_the_vehicle_page_and_its_relay_pacing(server: RunningServer) -> None:
    vehicle = embedded_config(httpx.get(f"{server.url}/vehicle?profile=follow").text)
    relay = embedded_config(httpx.get(f"{server.url}/relay?profile=follow").text)
    assert vehicle["profile"] == "follow"
    # The relay has no follow pacing of its own: it snapshots as for the default profile.
    assert relay["profile"] == PROFILES["follow"].relay_profile == "default"
    assert relay["operation"] is None  # the spec's default


def test_the_onboard_relay_starts_with_the_onboard_operation(server: RunningServer) -> None:
    relay = embedded_config(httpx.get(f"{server.url}/relay?profile=onboard").text)
    assert relay["profile"] == "default"
    assert relay["operation"] == PROFILES["onboard"].operation == "face_small"
    ops = {op.id for op in spec.load_spec(OPERATIONS_SPEC).operations}
    # Every profile's operation is one the relay offers.
    assert {p.operation for p in PROFILES.values()} - {None} <= ops


@pytest.mark.parametrize(("query", "standoff"), [("2.5", 2.5), ("0", 0.0), ("-1", 1.0), ("x", 1.0)])
def test_standoff_from_the_query_or_the_profile(
    server: RunningServer, query: str, standoff: float
) -> None:
    url = f"{server.url}/vehicle?profile=follow&standoff={query}"
    config = embedded_config(httpx.get(url).text)
    assert config["control"]["profiles"]["follow"]["standoffM"] == standoff
    assert PROFILES["follow"].standoff_m == 1.0  # the fallback the last two cases expect


def test_spawn_step_is_on_unless_switched_off(server: RunningServer) -> None:
    on = embedded_config(httpx.get(f"{server.url}/vehicle").text)
    off = embedded_config(httpx.get(f"{server.url}/vehicle?spawn=0").text)
    assert (on["spawnStep"], off["spawnStep"]) == (True, False)


def test_the_vehicle_page_drives_the_robot_it_is_given(server: RunningServer) -> None:
    default = embedded_config(httpx.get(f"{server.url}/vehicle").text)
    assert default["robot"]["description"]["name"] == "turtlesim"
    assert default["robot"]["teleportService"] == "/turtle1/teleport_absolute"
    assert default["robotError"] is None
    # turtlesim applies every command at once: no acceleration limit (JSON's null).
    assert default["robot"]["description"]["limits"]["linearAccel"] is None
    burger = embedded_config(httpx.get(f"{server.url}/vehicle?robot=turtlebot3").text)
    description = burger["robot"]["description"]
    assert (description["velocity"]["topic"], description["pose"]["type"]) == (
        "/cmd_vel",
        "nav_msgs/Odometry",
    )
    assert description["limits"] == {
        "maxLinear": 0.22,
        "maxAngular": 2.84,
        "linearAccel": 2.5,
        "angularAccel": 3.2,
    }
    assert burger["robot"]["types"]["pose"]["1"] == "nav_msgs/Odometry"
    # No spawn step (it is turtlesim's), however asked; not a turtlesim, so the page's pilot
    # fits its profile to a robot without the terrain's walls (core/pilot.js, with the limits
    # above). The profiles come as the protocol has them, whatever the robot.
    assert burger["spawnStep"] is False
    assert (burger["robot"]["turtlesim"], default["robot"]["turtlesim"]) == (False, True)
    assert burger["control"]["profiles"] == default["control"]["profiles"]


def test_an_unknown_robot_is_an_error_on_the_page(server: RunningServer) -> None:
    config = embedded_config(httpx.get(f"{server.url}/vehicle?robot=r2d2").text)
    assert "r2d2" in config["robotError"] and "turtlebot3" in config["robotError"]


@pytest.mark.parametrize("role", ROLES)
def test_a_page_holds_no_ice_servers_and_no_turn_secret(
    turn_server: RunningServer, role: str
) -> None:
    html = httpx.get(f"{turn_server.url}/{role}").text
    assert "iceServers" not in embedded_config(html)
    assert TURN_SECRET not in html and "turn.example" not in html


def test_query_text_cannot_break_out_of_the_config_script(server: RunningServer) -> None:
    evil = "</script><script>alert(1)</script>"
    html = httpx.get(f"{server.url}/client", params={"room": evil}).text
    assert "<script>alert(1)" not in html
    assert embedded_config(html)["room"] == evil


def test_client_has_exactly_the_thesis_buttons_the_console_s_and_a_labelled_operation_list(
    server: RunningServer,
) -> None:
    html = httpx.get(f"{server.url}/client").text
    parser = Buttons()
    parser.feed(html)
    thesis = ["Connect", "Join Room", "Leave Room", "Set Operation", "Start Piloting"]
    console = ["Stop robot", "Take Over", "Hand Back", "Unlock"]  # the operator's console
    assert sorted(parser.labels) == sorted([*thesis, "Stop Piloting", *console])
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


def test_the_relay_previews_its_video_unless_switched_off(server: RunningServer) -> None:
    on = embedded_config(httpx.get(f"{server.url}/relay").text)
    off = embedded_config(httpx.get(f"{server.url}/relay?preview=0").text)
    assert (on["preview"], off["preview"]) == (True, False)
