"""Tests of hcard_conformance: the suite's checks, its reports and the golden vectors."""
