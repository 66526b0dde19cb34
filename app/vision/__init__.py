"""Vision: the operations spec and the Python reference pipeline the relay's OpenCV.js mirrors."""
