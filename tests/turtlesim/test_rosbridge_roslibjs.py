"""``/rosbridge`` driven by roslib.js, the client the vehicle page uses, in headless Chromium."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest
from playwright.async_api import Page, async_playwright

from app.server.serve import RunningServer
from app.tools.browser import chromium_args, chromium_path
from app.turtlesim.sim import TurtleSim

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

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


@pytest.fixture
async def page(server: RunningServer) -> AsyncIterator[Page]:
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(
            executable_path=chromium_path(), args=chromium_args()
        )
        try:
            page = await browser.new_page()
            # Any page of the app gives roslib.js the server's origin; no CDN is involved.
            await page.goto(server.url + "/healthz")
            await page.add_script_tag(url=server.url + "/static/vendor/roslib.min.js")
            yield page
        finally:
            await browser.close()


async def test_roslibjs_subscribes_publishes_and_calls_services(
    page: Page, server: RunningServer
) -> None:
    url = server.url.replace("http", "ws", 1) + "/rosbridge"
    seen: dict[str, Any] = await page.evaluate(SCRIPT, url)
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
