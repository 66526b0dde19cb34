"""One way to put a validation failure into words, for every socket, channel and file."""

from __future__ import annotations

from pydantic import ValidationError


def describe(exc: ValidationError, *, skip: int = 0) -> str:
    """One line naming each bad field, e.g. ``field 'to': Field required``.

    ``skip`` drops leading location parts that are not fields (a tagged union's tag).
    """
    problems = []
    for error in exc.errors(include_url=False, include_input=False):
        loc = ".".join(str(part) for part in error["loc"][skip:]) or "message"
        problems.append(f"field {loc!r}: {error['msg']}")
    return "; ".join(problems)
