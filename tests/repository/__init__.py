"""Tests of the repository as a whole: the map in ARCHITECTURE.md and the layers of the imports,
the declared dependencies, the spec's rule identifiers and printed examples."""
