"""Tests of the command line (hcard.cli): its commands, options, exit statuses, console script."""
