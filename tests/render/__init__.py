"""Tests of the renderer (hcard.render): its numbers, its crossings, its streamed output."""
