"""The hcard conformance suite: format, renderer and device levels, run by vendors and CI."""
