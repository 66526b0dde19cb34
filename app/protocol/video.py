"""The vehicle's video: its size and frame rate, and the size of the relay's forward.

The relay analyses one snapshot per decoded frame, so the frame rate bounds goals per second and
the wait for the next frame is part of every goal's latency.
"""

from __future__ import annotations

from typing import Final

# The size a browser vehicle asks its camera for, and the Python agent's synthetic scene.
VIDEO_SIZE: Final = (640, 480)
# The agent's frame rate.
VIDEO_FPS: Final = 30.0
# Where the relay cannot pass the vehicle's encoded frames through to a client (its browser has
# no encoded transforms, or the client does not receive the vehicle's codec: docs/contracts.md,
# "Video forward"), it encodes the video again for that client at this fraction of its size per
# side (RTCRtpEncodingParameters.scaleResolutionDownBy): the operator watches it, the relay
# analyses the full-size decoded frames, and that encode is the relay's largest cost after the
# cascade (docs/bench/relay-cost.md).
CLIENT_FORWARD_SCALE_DOWN: Final = 2.0
