"""Every message type the pages write is a protocol model, received by the side it goes to.

The pages build their messages as object literals (``{ type: 'goal', ... }``); this reads each
``type: '<name>'`` out of the role modules and checks it against the signaling models and the
data-channel receivers of ``app/protocol``. A page that starts sending a type the protocol does
not define, or sends one to a side that does not accept it, fails here.
"""

from __future__ import annotations

import re

from app.protocol import channels
from app.protocol.channels import AUTOPILOT_CHANNEL, CONTROL_CHANNEL
from app.protocol.signaling import INCOMING_TYPES
from app.resources import STATIC_DIR

JS = STATIC_DIR / "js"
TYPE_LITERAL = re.compile(r"\btype: '(\w+)'")

# What each module sends on a data channel: (module, channel, receiving role, types).
CHANNEL_SENDS = [
    ("pages/vehicle.js", AUTOPILOT_CHANNEL, "relay", {"pose"}),
    # askRelay(type) sends start/stop on `control` when signaling is down.
    ("pages/client.js", CONTROL_CHANNEL, "relay", {"getOps", "setOp", "start", "stop"}),
    ("pages/client.js", CONTROL_CHANNEL, "relay", {"takeOver", "handBack", "drive", "stopRobot"}),
    (
        "pages/relay.js",
        CONTROL_CHANNEL,
        "client",
        {"state", "ops", "error", "pose", "health", "robotStopped"},
    ),
    ("pages/relay.js", AUTOPILOT_CHANNEL, "vehicle", {"stop"}),
    # The operator seat's mode changes go to the vehicle and the clients, its drives to the vehicle.
    ("core/relay-seats.js", CONTROL_CHANNEL, "client", {"mode"}),
    ("core/relay-seats.js", AUTOPILOT_CHANNEL, "vehicle", {"mode", "drive"}),
    ("core/snapshot-loop.js", AUTOPILOT_CHANNEL, "vehicle", {"goal"}),
    ("core/snapshot-loop.js", CONTROL_CHANNEL, "client", {"detections", "lockState"}),
    ("view/lock-view.js", CONTROL_CHANNEL, "relay", {"lock", "unlock"}),
    # serveChannel's error replies go back on whichever channel the bad message came from.
    ("net/peer.js", AUTOPILOT_CHANNEL, "vehicle", {"error"}),
]
SENT_ON_CHANNEL = {(module, kind) for module, _, _, kinds in CHANNEL_SENDS for kind in kinds}
MODULES = sorted({module for module, _ in SENT_ON_CHANNEL} | {"net/room.js", "net/signaling.js"})


def test_every_type_a_page_writes_is_a_signaling_or_channel_model() -> None:
    channel_types = {channels.type_of(m) for m in channels.ChannelMessage.__args__}
    for module in MODULES:
        for kind in TYPE_LITERAL.findall((JS / module).read_text()):
            sent_on_channel = (module, kind) in SENT_ON_CHANNEL
            assert sent_on_channel or kind in INCOMING_TYPES, f"{module} writes {kind!r}"
            if sent_on_channel:
                assert kind in channel_types


def test_each_channel_message_goes_to_a_side_that_accepts_it() -> None:
    for module, label, role, kinds in CHANNEL_SENDS:
        accepted = {channels.type_of(m) for m in channels.RECEIVERS[label][role]}
        for kind in kinds:
            assert kind in accepted, f"{module} sends {kind!r} to the {role} on {label!r}"


def test_error_replies_are_accepted_on_every_channel_by_every_side() -> None:
    for by_role in channels.RECEIVERS.values():
        for models in by_role.values():
            assert channels.Error in models
