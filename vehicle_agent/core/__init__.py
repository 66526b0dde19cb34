"""The vehicle's pure core: what it decides, without I/O (twins of app/static/js/core/)."""
