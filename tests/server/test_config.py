"""Settings refuse numbers the server cannot use, naming the setting (app/server/config.py)."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pydantic import ValidationError

from app.server.config import Settings


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("port", 0),
        ("port", 65536),
        # An infinite login timeout would never close a socket that does not log in.
        ("login_timeout_s", math.inf),
        ("login_timeout_s", math.nan),
        ("login_timeout_s", 0),
    ],
)
def test_a_setting_out_of_range_is_refused_by_name(field: str, value: Any) -> None:
    with pytest.raises(ValidationError, match=field):
        Settings(**{field: value})


def test_the_defaults_are_valid() -> None:
    settings = Settings()
    assert settings.port == 8000
    assert settings.login_timeout_s == 10.0
