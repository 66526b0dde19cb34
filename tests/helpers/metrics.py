"""Reading a ``/metrics`` endpoint as the tests do: every sample, keyed by name and labels."""

from __future__ import annotations

import urllib.request

from prometheus_client.parser import text_string_to_metric_families

Samples = dict[tuple[str, tuple[tuple[str, str], ...]], float]


def scrape(url: str) -> Samples:
    """``/metrics`` at ``url``, parsed: (sample name, sorted labels) -> value; empty while
    nothing listens there yet."""
    try:
        with urllib.request.urlopen(url, timeout=5) as response:
            text = response.read().decode()
    except OSError:
        return {}
    return {
        (sample.name, tuple(sorted(sample.labels.items()))): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


def peers(url: str) -> dict[str, float]:
    """``autopilot_peers`` by role at ``url``."""
    return {
        dict(labels)["role"]: value
        for (name, labels), value in scrape(url).items()
        if name == "autopilot_peers"
    }
