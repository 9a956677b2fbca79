"""Built-in plugins of hcard, registered through the ``hcard.plugins`` entry point group like any
vendor package (see ``[project.entry-points."hcard.plugins"]`` in pyproject.toml)."""
