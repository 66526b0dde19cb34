"""Reading a robot description file (app/robot_file.py): good files, files refused in one line
naming the key (a bad value, an unknown key, hostile sizes, numbers, nesting and characters),
what is not a regular file, and ``--robot FILE`` ending a command with that one line."""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from app.arguments import add_robot_option
from app.protocol.robot import MAX_NAME_CHARS, MAX_TOPIC_CHARS, PRESETS, RobotError
from app.robot_file import MAX_FILE_BYTES, MAX_NESTING, load, nesting_problem, robot_named

ROVER = """
name = "rover"

[velocity]
topic = "/base/cmd_vel"
type = "geometry_msgs/TwistStamped"
frame_id = "base_footprint"

[pose]
topic = "odom"
type = "nav_msgs/msg/Odometry"

[camera]
topic = "/front/image_raw"
type = "sensor_msgs/Image"
hfov_deg = 87

[limits]
max_linear = 0.5
max_angular = 1
linear_accel = 0.8
angular_accel = inf
"""


VELOCITY_TABLE = ROVER[ROVER.index("[velocity]") : ROVER.index("[pose]")]


def write(tmp_path: Path, text: str, name: str = "rover.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_file_describes_a_robot(tmp_path: Path) -> None:
    robot = load(write(tmp_path, ROVER))
    assert robot.name == "rover"
    assert (robot.velocity.topic, robot.velocity.type, robot.velocity.frame_id) == (
        "/base/cmd_vel",
        "geometry_msgs/TwistStamped",
        "base_footprint",
    )
    # A relative topic is the root namespace's; a ROS 2 spelling of a type is read back.
    assert (robot.pose.topic, robot.pose.type) == ("/odom", "nav_msgs/Odometry")
    assert robot.camera is not None
    assert (robot.camera.topic, robot.camera.type, robot.camera.hfov_deg) == (
        "/front/image_raw",
        "sensor_msgs/Image",
        87.0,
    )
    assert robot.limits.max_angular == 1.0 and robot.limits.angular_accel == math.inf
    assert not robot.turtlesim and robot.teleport_service is None


def test_a_minimal_file_takes_its_name_from_the_file_and_has_no_camera(tmp_path: Path) -> None:
    text = (
        ROVER.split("[camera]")[0].replace('name = "rover"', "") + ROVER.split("hfov_deg = 87")[1]
    )
    text = text.replace('frame_id = "base_footprint"\n', "")
    robot = load(write(tmp_path, text, "my-base.toml"))
    assert robot.name == "my-base"
    assert robot.camera is None
    assert robot.velocity.frame_id == "base_link"  # a TwistStamped's default frame


def test_a_preset_is_found_by_name() -> None:
    assert robot_named("turtlebot3") is PRESETS["turtlebot3"]


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        # unknown keys, at the top and in a table
        (('name = "rover"', 'name = "rover"\ncolour = "red"'), ["colour: unknown key"]),
        (("max_linear = 0.5", "max_linear = 0.5\nmax_lateral = 1"), ["limits.max_lateral"]),
        # wrong types
        (("max_linear = 0.5", "max_linear = 'fast'"), ["limits.max_linear", "number", "'fast'"]),
        (("max_linear = 0.5", "max_linear = true"), ["limits.max_linear", "boolean"]),
        (('topic = "odom"', "topic = 7"), ["pose.topic", "string"]),
        ((VELOCITY_TABLE, 'velocity = "/base/cmd_vel"\n'), ["velocity: must be a table"]),
        # bad values
        (("max_linear = 0.5", "max_linear = -0.5"), ["limits.max_linear", ">= 0", "-0.5"]),
        (("angular_accel = inf", "angular_accel = 0"), ["limits.angular_accel", "> 0"]),
        (("max_angular = 1", "max_angular = nan"), ["limits.max_angular", "nan"]),
        (("hfov_deg = 87", "hfov_deg = 190"), ["camera.hfov_deg", "180"]),
        (('topic = "odom"', 'topic = "my odom"'), ["pose.topic", "not a ROS topic name"]),
        # unknown message types
        (('"geometry_msgs/TwistStamped"', '"geometry_msgs/Twst"'), ["velocity.type", "Twst"]),
        (('"nav_msgs/msg/Odometry"', '"geometry_msgs/PoseStamped"'), ["pose.type", "unknown"]),
        (('"sensor_msgs/Image"', '"sensor_msgs/LaserScan"'), ["camera.type", "LaserScan"]),
        # missing keys and tables
        (('topic = "/base/cmd_vel"', ""), ["velocity.topic", "missing"]),
        (('topic = "odom"', ""), ["pose.topic", "missing"]),
        (("linear_accel = 0.8", ""), ["limits.linear_accel", "missing"]),
        (("[limits]", "[limited]"), ["limited", "unknown key"]),
        # a header only a TwistStamped has
        (('"geometry_msgs/TwistStamped"', '"geometry_msgs/Twist"'), ["velocity.frame_id"]),
    ],
)
def test_a_bad_file_is_one_line_naming_the_key(
    tmp_path: Path, change: tuple[str, str], needles: list[str]
) -> None:
    assert change[0] in ROVER
    path = write(tmp_path, ROVER.replace(change[0], change[1], 1))
    with pytest.raises(RobotError) as raised:
        load(path)
    message = str(raised.value)
    assert "\n" not in message
    assert str(path) in message
    for needle in needles:
        assert needle in message, message


def test_a_file_that_is_not_toml_or_not_there(tmp_path: Path) -> None:
    with pytest.raises(RobotError, match=r"not TOML.*line 2"):
        load(write(tmp_path, "name = 'x'\n[velocity\n"))
    with pytest.raises(RobotError, match="no robot preset named 'rover3'.*no such file"):
        robot_named("rover3")


# -- hostile files ---------------------------------------------------------------------------


def refusal(path: Path) -> str:
    """The one line ``load`` refuses ``path`` with (a RobotError, never another exception)."""
    with pytest.raises(RobotError) as raised:
        load(path)
    message = str(raised.value)
    assert message.startswith((f"robot file {path}", f"cannot read robot file {path}")), message
    # One line, and nothing a terminal would act on: a name cannot forge a log line.
    assert message.isprintable(), repr(message)
    assert len(message) < 400, message
    return message


def test_the_limits_are_the_documented_ones() -> None:
    assert MAX_FILE_BYTES == 65536
    assert MAX_NESTING == 4
    assert (MAX_NAME_CHARS, MAX_TOPIC_CHARS) == (64, 256)


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        # Integers beyond the float range (float() of one overflows), either sign.
        (("max_linear = 0.5", "max_linear = " + "9" * 400), ["limits.max_linear", "float range"]),
        (("hfov_deg = 87", "hfov_deg = -" + "1" * 310), ["camera.hfov_deg", "float range"]),
        # One longer than Python converts at all: tomllib refuses it, in one line too.
        (("max_linear = 0.5", "max_linear = " + "7" * 5000), ["integer too long"]),
        # Control characters: an ANSI escape, a line break, a bell, in a name or a frame id.
        (('name = "rover"', r'name = "rover\u001b[31m red"'), ["name", "control characters"]),
        (('name = "rover"', r'name = "rover\nINFO forged"'), ["name", "control characters"]),
        (('"base_footprint"', r'"base\u0007"'), ["velocity.frame_id", "control characters"]),
        # ... or in a key's own name, which the error shows escaped.
        (('name = "rover"', 'name = "rover"\n"\\u001b[2J" = 1'), ["unknown key", r"\x1b"]),
        # Over-long names, frame ids, topics and types.
        (('name = "rover"', f'name = "{"r" * 65}"'), ["name", "at most 64 characters, not 65"]),
        (('"base_footprint"', f'"{"f" * 65}"'), ["velocity.frame_id", "at most 64"]),
        (('topic = "odom"', f'topic = "/{"o" * 256}"'), ["pose.topic", "at most 256", "257"]),
        (('"sensor_msgs/Image"', f'"{"s" * 300}"'), ["camera.type", "at most 256"]),
        (('"sensor_msgs/Image"', f'"{"s" * 200}"'), ["camera.type", "unknown", "200 characters"]),
        # Nesting: arrays, inline tables, dotted keys, table headers.
        (('name = "rover"', 'name = "rover"\ncolour = ' + "[" * 5000 + "]" * 5000), ["deep"]),
        (('name = "rover"', 'name = "rover"\nc = ' + "{a = " * 3000 + "1" + "}" * 3000), ["deep"]),
        (('name = "rover"', 'name = "rover"\n' + "a." * 20000 + "b = 1"), ["dotted parts"]),
        (("[limits]", "[limits.a.b.c.d]"), ["dotted parts"]),
        # Not UTF-8.
        (('name = "rover"', 'name = "rover\udcff"'), ["not UTF-8"]),
    ],
)
def test_a_hostile_file_is_one_line_naming_the_key(
    tmp_path: Path, change: tuple[str, str], needles: list[str]
) -> None:
    assert change[0] in ROVER
    path = tmp_path / "rover.toml"
    path.write_bytes(ROVER.replace(*change, 1).encode("utf-8", "surrogateescape"))
    message = refusal(path)
    for needle in needles:
        assert needle in message, message


def test_nesting_names_the_line_and_the_key(tmp_path: Path) -> None:
    deep = ROVER.replace('name = "rover"', 'name = "rover"\ncolour = ' + "[" * 5 + "]" * 5)
    message = refusal(write(tmp_path, deep))
    assert "line 3, key 'colour'" in message and f"more than {MAX_NESTING} deep" in message
    # Four levels, and dotted keys of four parts, are within the limit.
    assert nesting_problem("a = " + "[" * 4 + "]" * 4) is None
    assert nesting_problem("a.b.c.d = 1") is None
    assert nesting_problem("[a.b.c.d]") is None
    assert nesting_problem("a.b.c.d.e = 1") is not None


@pytest.mark.parametrize(
    "text",
    [
        # What nests inside strings and comments is text, and a number's dot is no key's.
        'name = "[[[[[[{{{{{{ a.b.c.d.e.f"\n',
        "name = '[[[[[[ a.b.c.d.e.f'\n",
        'name = """\n[[[[[[\n"""\n',
        "name = '''\n{{{{{{ '''\n",
        'name = "quote \\" [[[[[["\n',
        "# [[[[[[ a.b.c.d.e.f\n",
        "x = [1.5, 2.25, [3.5, [4.5]]]\n",
        "when = 1979-05-27T07:32:00.999999-07:00\n",
    ],
)
def test_brackets_and_dots_in_strings_comments_and_numbers_are_not_nesting(text: str) -> None:
    assert nesting_problem(text) is None


def test_the_file_is_read_up_to_its_bound_and_no_further(tmp_path: Path) -> None:
    padded = ROVER + "#" * (MAX_FILE_BYTES - len(ROVER.encode()) - 1) + "\n"
    assert len(padded.encode()) == MAX_FILE_BYTES
    assert load(write(tmp_path, padded)).name == "rover"
    message = refusal(write(tmp_path, padded + "#", "big.toml"))
    assert f"more than {MAX_FILE_BYTES} bytes" in message


def test_a_name_or_topic_at_the_limit_is_taken(tmp_path: Path) -> None:
    text = ROVER.replace('name = "rover"', f'name = "{"r" * MAX_NAME_CHARS}"').replace(
        'topic = "odom"', f'topic = "/{"o" * (MAX_TOPIC_CHARS - 1)}"'
    )
    robot = load(write(tmp_path, text))
    assert len(robot.name) == MAX_NAME_CHARS and len(robot.pose.topic) == MAX_TOPIC_CHARS


def test_a_file_name_that_would_forge_a_line_is_no_robot_name(tmp_path: Path) -> None:
    path = write(tmp_path, ROVER.replace('name = "rover"', ""), "rover\x1b[31m.toml")
    with pytest.raises(RobotError) as raised:
        load(path)
    message = str(raised.value)
    assert "name: must not hold control characters" in message
    assert "\x1b" not in message.removeprefix(f"robot file {path}")


@pytest.mark.parametrize("kind", ["device", "fifo", "directory"])
def test_only_a_regular_file_is_read(tmp_path: Path, kind: str) -> None:
    if kind == "device":
        path = Path("/dev/zero")
    elif kind == "fifo":
        path = tmp_path / "robot.toml"
        os.mkfifo(path)
    else:
        path = tmp_path
    answer: list[str] = []
    # A FIFO opened for reading blocks until a writer comes: the refusal must not wait.
    reader = threading.Thread(target=lambda: answer.append(refusal(path)), daemon=True)
    reader.start()
    reader.join(timeout=10)
    assert answer and "not a regular file" in answer[0], answer


def test_robot_option_refuses_a_bad_file_in_one_line_and_status_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(tmp_path, ROVER.replace("max_linear = 0.5", "max_linear = " + "9" * 400))
    parser = argparse.ArgumentParser(prog="autopilot vehicle")
    add_robot_option(parser, "the robot driven")
    with pytest.raises(SystemExit) as ended:
        parser.parse_args(["--robot", str(path)])
    assert ended.value.code == 2
    out, err = capsys.readouterr()
    assert out == ""
    [line] = err.splitlines()  # no usage block before it
    assert line.startswith("autopilot vehicle: error: argument --robot: robot file ")
    assert "limits.max_linear" in line
    assert parser.parse_args(["--robot", "turtlebot3"]).robot is PRESETS["turtlebot3"]


def test_the_command_prints_only_that_line(tmp_path: Path) -> None:
    path = write(tmp_path, ROVER.replace('name = "rover"', r'name = "rover\u001b[31m"'))
    done = subprocess.run(
        [sys.executable, "-m", "app.cli", "vehicle", "--robot", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    [line] = done.stderr.splitlines()
    assert line.startswith("autopilot vehicle: error: argument --robot: robot file ")
    assert "name: must not hold control characters" in line and "\x1b" not in line
