"""webrtc-autopilot: pilot a ROS turtle from OpenCV.js analysis of its own WebRTC video."""
