"""``/rosbridge`` driven by roslib.js, the client the vehicle page uses, in headless Chromium."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
import pytest_asyncio
from playwright.async_api import Page

from app.protocol.ros import RosFlavour
from app.server.config import Settings
from app.server.serve import RunningServer
from app.turtlesim.sim import TurtleSim

# One Chromium for the module, a context per test (tests/conftest.py), on the module's loop.
pytestmark = [
    pytest.mark.browser,
    pytest.mark.timeout(120),
    pytest.mark.asyncio(loop_scope="module"),
]

# Runs in the page: talks to /rosbridge the way the vehicle page does, and reports what it saw.
SCRIPT = """
async (url) => {
  const until = (condition, what, ms = 15000) => new Promise((resolve, reject) => {
    const started = Date.now();
    const poll = () => {
      if (condition()) return resolve();
      if (Date.now() - started > ms) return reject(new Error(`timed out waiting for ${what}`));
      setTimeout(poll, 10);
    };
    poll();
  });
  const call = (name, type, args) => new Promise((resolve) => {
    const service = new ROSLIB.Service({ros, name, serviceType: type});
    service.callService(new ROSLIB.ServiceRequest(args),
      (values) => resolve({ok: true, values}), (error) => resolve({ok: false, error}));
  });

  const ros = new ROSLIB.Ros({url});
  await new Promise((resolve, reject) => {
    ros.on('connection', resolve);
    ros.on('error', () => reject(new Error('roslib.js could not connect')));
  });
  const poses = [];
  const pose = new ROSLIB.Topic({ros, name: '/turtle1/pose', messageType: 'turtlesim/Pose'});
  pose.subscribe((message) => poses.push(message));
  await until(() => poses.length > 0, 'a first pose');
  const start = poses[poses.length - 1];

  const cmdVel = new ROSLIB.Topic(
    {ros, name: '/turtle1/cmd_vel', messageType: 'geometry_msgs/Twist'});
  cmdVel.publish(new ROSLIB.Message(
    {linear: {x: 0, y: 0, z: 0}, angular: {x: 0, y: 0, z: 1.5}}));
  await until(() => poses[poses.length - 1].theta > 0.5, 'the turtle to turn');
  const turned = poses[poses.length - 1];

  const spawned = await call('/spawn', 'turtlesim/Spawn', {x: 1, y: 2, theta: 0, name: ''});
  const failed = await call('/kill', 'turtlesim/Kill', {name: 'nobody'});
  pose.unsubscribe();
  ros.close();
  return {start, turned, spawned, failed};
}
"""


@pytest_asyncio.fixture(loop_scope="module")
async def roslib_page(context_page: Page, server: RunningServer) -> Page:
    """A page of the app (any gives roslib.js the server's origin; no CDN is involved) with
    roslib.js loaded."""
    await context_page.goto(server.url + "/healthz")
    await context_page.add_script_tag(url=server.url + "/static/vendor/roslib.min.js")
    return context_page


async def test_roslibjs_subscribes_publishes_and_calls_services(
    roslib_page: Page, server: RunningServer
) -> None:
    url = server.url.replace("http", "ws", 1) + "/rosbridge"
    seen: dict[str, Any] = await roslib_page.evaluate(SCRIPT, url)
    centre = TurtleSim.WORLD_SIZE / 2
    start, turned = seen["start"], seen["turned"]
    assert (start["x"], start["y"], start["theta"]) == pytest.approx((centre, centre, 0.0))
    assert turned["theta"] > 0.5
    assert turned["angular_velocity"] == 1.5
    # Turning in place: the turtle stays where it was.
    assert (turned["x"], turned["y"]) == pytest.approx((centre, centre))
    assert seen["spawned"] == {"ok": True, "values": {"name": "turtle2"}}
    assert seen["failed"]["ok"] is False
    assert "nobody" in seen["failed"]["error"]


# Runs in the page: the rosapi calls tools make through roslib.js's own helpers.
ROSAPI_SCRIPT = """
async (url) => {
  const ros = new ROSLIB.Ros({url});
  await new Promise((resolve, reject) => {
    ros.on('connection', resolve);
    ros.on('error', () => reject(new Error('roslib.js could not connect')));
  });
  const ask = (method, ...args) => new Promise((resolve, reject) =>
    ros[method](...args, (...values) => resolve(values.length === 1 ? values[0] : values),
                (error) => reject(new Error(`${method}: ${error}`))));
  const topics = await ask('getTopics');
  const raw = await ask('getTopicsAndRawTypes');
  const poseType = await ask('getTopicType', '/turtle1/pose');
  const services = await ask('getServices');
  const spawnType = await ask('getServiceType', '/spawn');
  const nodes = await ask('getNodes');
  const [subscribing, publishing, served] = await ask('getNodeDetails', '/turtlesim');
  const params = await ask('getParams');
  const name = params.find((p) => p.endsWith('background_g'));
  const param = new ROSLIB.Param({ros, name});
  const green = await new Promise((resolve) => param.get(resolve));
  await new Promise((resolve) => param.set(120, resolve));
  const greenAfter = await new Promise((resolve) => param.get(resolve));
  ros.close();
  return {topics, raw, poseType, services, spawnType, nodes, subscribing, publishing, served,
          params, name, green, greenAfter};
}
"""

POSE_TYPE = {"1": "turtlesim/Pose", "2": "turtlesim/msg/Pose", "jazzy": "turtlesim_msgs/msg/Pose"}


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
async def test_roslibjs_rosapi_helpers(
    context_page: Page, start_server: Callable[[Settings], RunningServer], flavour: RosFlavour
) -> None:
    robot = start_server(Settings(environment="development", token=None, ros=flavour))
    # The page must come from the robot's own origin: its /rosbridge refuses other sites.
    await context_page.goto(robot.url + "/healthz")
    await context_page.add_script_tag(url=robot.url + "/static/vendor/roslib.min.js")
    url = robot.url.replace("http", "ws", 1) + "/rosbridge"
    seen: dict[str, Any] = await context_page.evaluate(ROSAPI_SCRIPT, url)
    listed = dict(zip(seen["topics"]["topics"], seen["topics"]["types"], strict=True))
    assert listed["/turtle1/pose"] == POSE_TYPE[flavour]
    assert "/rosout" in listed
    raw = seen["raw"]
    assert len(raw["typedefs_full_text"]) == len(raw["topics"])
    assert seen["poseType"] == POSE_TYPE[flavour]
    assert "/turtle1/set_pen" in seen["services"]
    assert seen["spawnType"].endswith("Spawn")
    assert "/turtlesim" in seen["nodes"]
    assert "/turtle1/cmd_vel" in seen["subscribing"]
    assert "/turtle1/pose" in seen["publishing"]
    assert "/spawn" in seen["served"]
    sep = "/" if flavour == "1" else ":"
    assert seen["name"] == f"/turtlesim{sep}background_g"
    assert (seen["green"], seen["greenAfter"]) == (86, 120)
