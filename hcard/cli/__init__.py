"""The ``hcard`` command line (click)."""
