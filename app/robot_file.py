"""Reading a robot description file (``--robot FILE``, docs/robots.md) into a
:class:`~app.protocol.robot.Robot`.

The file is untrusted input: it is read only if it is a regular file (a device such as
``/dev/zero`` would never end, a FIFO would block), and only its first :data:`MAX_FILE_BYTES`;
its TOML may nest arrays, inline tables and dotted keys at most :data:`MAX_NESTING` deep, checked
before ``tomllib`` parses it (which recurses on nesting, and slows to seconds on a long dotted
key); then :func:`app.protocol.robot.parse` checks the description. Whatever is wrong is one
:class:`~app.protocol.robot.RobotError` line naming the file and the key.
"""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path
from typing import Final

from app.protocol.robot import PRESETS, Robot, RobotError, parse

# A description is a few hundred bytes; this leaves room for comments and nothing more.
MAX_FILE_BYTES: Final = 64 * 1024
# A description needs a table of keys (two parts, or one inline table): this is ample for it.
MAX_NESTING: Final = 4
# How much of a key the nesting error names.
_KEY_SHOWN_CHARS: Final = 40


def load(path: Path) -> Robot:
    """The robot a TOML description file describes; :class:`RobotError` (one line, naming the
    file and the key) if it cannot be read or describes no robot."""
    text = _read(path)
    if (problem := nesting_problem(text)) is not None:
        raise RobotError(f"robot file {path}: {problem}")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RobotError(f"robot file {path}: not TOML: {exc}") from None
    except ValueError:  # an integer longer than Python converts (tomllib lets it through)
        raise RobotError(
            f"robot file {path}: an integer too long to read (numbers are within the float range)"
        ) from None
    try:
        return parse(data, path.stem)
    except RobotError as exc:
        raise RobotError(f"robot file {path}: {exc}") from None


def robot_named(text: str) -> Robot:
    """A preset by name, else the description file at ``text``; :class:`RobotError` if it is
    neither."""
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if not path.exists():
        raise RobotError(
            f"no robot preset named {text!r} (one of {', '.join(PRESETS)}) and no such file"
        )
    return load(path)


def _read(path: Path) -> str:
    """The text of the regular file at ``path``, at most :data:`MAX_FILE_BYTES` of UTF-8."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            raise RobotError(f"robot file {path}: not a regular file")
        # Non-blocking: should the path have become a FIFO since, opening it does not wait.
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(descriptor, "rb") as file:
            if not stat.S_ISREG(os.fstat(file.fileno()).st_mode):
                raise RobotError(f"robot file {path}: not a regular file")
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise RobotError(f"cannot read robot file {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise RobotError(
            f"robot file {path}: more than {MAX_FILE_BYTES} bytes (a description is a few hundred)"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RobotError(f"robot file {path}: not UTF-8 text (byte {exc.start})") from None


def nesting_problem(text: str) -> str | None:
    """Why the TOML ``text`` nests deeper than :data:`MAX_NESTING` (naming the line, and the key
    being given a value), or None.

    A scan of what nests -- brackets and braces, and the dots of dotted keys and table headers
    -- outside strings and comments. Dots are counted between separators (``, = [ ] { }`` and
    line ends), so a number (one dot at most) never counts as nesting.
    """
    depth = dots = 0
    line = 1
    key = ""
    start = 0  # where the text between separators began
    i = 0
    while i < len(text):
        c = text[i]
        if c in "\"'":
            quote = c * 3 if text.startswith(c * 3, i) else c
            end = _string_end(text, i + len(quote), quote)
            line += text.count("\n", i, end)
            i = end
            continue
        if c == "#":
            end = text.find("\n", i)
            i = len(text) if end < 0 else end
            continue
        if c == ".":
            dots += 1
            if dots >= MAX_NESTING:
                return f"line {line}: a key of more than {MAX_NESTING} dotted parts"
        elif c in ",=[]{}\n":
            if c == "=" and depth == 0:
                key = text[start:i].strip()
            dots, start = 0, i + 1
            if c in "[{":
                depth += 1
                if depth > MAX_NESTING:
                    shown = repr(key[:_KEY_SHOWN_CHARS])
                    return (
                        f"line {line}, key {shown}: arrays or inline tables nested more than "
                        f"{MAX_NESTING} deep"
                    )
            elif c in "]}":
                depth = max(depth - 1, 0)
            elif c == "\n":
                line += 1
        i += 1
    return None


def _string_end(text: str, i: int, quote: str) -> int:
    """Where the string whose content starts at ``i`` ends: just past its closing ``quote``; at
    the line's end for a one-line string left open (bad TOML, which tomllib reports); or at the
    text's end."""
    escapes = quote[0] == '"'  # basic strings have escapes, literal ones (') none
    while i < len(text):
        if escapes and text[i] == "\\":
            i += 2
        elif text[i] == "\n" and len(quote) == 1:
            return i
        elif text.startswith(quote, i):
            return i + len(quote)
        else:
            i += 1
    return len(text)
