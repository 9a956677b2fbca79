"""Tests of the plugin system (hcard.plugins): the registry, discovery, its cache, contributions."""
