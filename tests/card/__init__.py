"""Tests of the hcard package's own modules (hcard/*.py, hcard/v1): loading, saving and validating
cards, and the vocabulary under them (quantities, channels, errors, strict JSON, bounded reads,
atomic writes, terminal text), against hostile input too."""
