"""The JSON edge: every frame from a peer is parsed here, every frame to a peer is written here.

Python's ``json`` accepts more than JSON and more than the other side can handle: the literals
``NaN`` and ``Infinity`` (which browsers' ``JSON.parse`` refuses), ``1e999`` (infinity), integers
of thousands of digits (``int()`` refuses past 4300 digits with a ``ValueError`` that is not a
``JSONDecodeError``), nesting deep enough to raise ``RecursionError``, and bytes that are not
UTF-8. :func:`loads` turns each of these into one :class:`JsonEdgeError` with a sentence a peer can
read, so every caller needs one ``except``; :func:`dumps` never writes NaN or Infinity, and
writes ``bytes`` in base64.
"""

from __future__ import annotations

import base64
import json
import math
from typing import Any, Final

# Containers inside containers deeper than this are refused: no message of ours nests past 6.
MAX_DEPTH: Final = 32
# Integers with more digits than this are refused before they are converted; 2**63 has 19.
MAX_INT_DIGITS: Final = 20
# ... and so are integers outside the 64-bit range, which no ROS field or JS number holds exactly.
MAX_INT: Final = 2**63


class JsonEdgeError(ValueError):
    """A frame that is not JSON this system accepts; ``str(error)`` says why, for the peer."""


def oversize(text: str, limit: int) -> str | None:
    """Why a text frame is too large for ``limit`` bytes, or None when it fits."""
    size = len(text.encode("utf-8"))
    if size > limit:
        return f"message of {size} bytes exceeds the limit of {limit} bytes"
    return None


def _refuse_constant(name: str) -> Any:
    raise JsonEdgeError(f"{name} is not valid JSON: numbers must be finite")


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise JsonEdgeError(f"integer of {digits} digits is too large (limit {MAX_INT_DIGITS})")
    value = int(text)
    if not -MAX_INT <= value <= MAX_INT:
        raise JsonEdgeError(f"integer {text} is outside the range ±2**63")
    return value


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise JsonEdgeError(f"number {text[:40]} is too large: numbers must be finite")
    return value


def loads(data: str | bytes) -> Any:
    """Parse one frame; raises :class:`JsonEdgeError` naming the problem, and nothing else."""
    if isinstance(data, bytes | bytearray):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise JsonEdgeError(f"invalid UTF-8 at byte {exc.start}") from None
    try:
        value = json.loads(
            data,
            parse_constant=_refuse_constant,
            parse_int=_parse_int,
            parse_float=_parse_float,
        )
    except JsonEdgeError:
        raise
    except json.JSONDecodeError as exc:
        raise JsonEdgeError(f"malformed JSON: {exc.msg} at position {exc.pos}") from None
    except RecursionError:
        raise JsonEdgeError(f"malformed JSON: nested deeper than {MAX_DEPTH} levels") from None
    except ValueError as exc:  # int()/float() on a number the scanner accepted
        raise JsonEdgeError(f"malformed JSON: {exc}") from None
    if _depth(value) > MAX_DEPTH:
        raise JsonEdgeError(f"malformed JSON: nested deeper than {MAX_DEPTH} levels")
    return value


def dumps(value: Any) -> str:
    """Serialise a message for a peer; ``ValueError`` if it holds NaN or Infinity. ``bytes`` (a
    ROS ``uint8[]``, an image's data) are written in base64, as rosbridge writes them."""
    return json.dumps(value, allow_nan=False, separators=(",", ":"), default=_base64)


def _base64(value: Any) -> str:
    if isinstance(value, bytes):
        return base64.b64encode(value).decode("ascii")
    raise TypeError(f"{type(value).__name__} is not JSON")


def _depth(value: Any) -> int:
    """Nesting depth of parsed JSON, without recursion (a scalar is 0, ``[]`` is 1)."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children: Any = item.values()
        elif isinstance(item, list):
            children = item
        else:
            continue
        depth += 1
        if depth > MAX_DEPTH:
            return depth
        deepest = max(deepest, depth)
        stack.extend((child, depth) for child in children)
    return deepest
