"""Tests of the preview picture (hcard.preview): periods, the error map, glyph labels."""
