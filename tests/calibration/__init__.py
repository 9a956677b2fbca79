"""Tests of hcard.calibration: the protocol, the fits, the effects, the search and its report."""
