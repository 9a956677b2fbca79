"""The committed generated code is exactly what protoc makes of the committed .proto."""

from __future__ import annotations

import importlib.util

import pytest

from tests.helpers.repository import REPO as ROOT
from tests.helpers.repository import import_script


def test_generated_code_matches_the_proto(tmp_path):
    if importlib.util.find_spec("grpc_tools") is None:
        pytest.fail("grpcio-tools is missing: install the dev extra (pip install -e '.[dev]')")
    generate = import_script("scripts/generate_proto.py").generate

    for fresh in generate(tmp_path):
        committed = ROOT / fresh.relative_to(tmp_path)
        assert committed.read_text() == fresh.read_text(), (
            f"{committed.relative_to(ROOT)} is stale: run python scripts/generate_proto.py"
        )


def test_generated_code_imports_without_protoc():
    from hcard.v1 import card_pb2

    assert card_pb2.Card.DESCRIPTOR.full_name == "hcard.v1.Card"
    assert card_pb2.DESCRIPTOR.package == "hcard.v1"
