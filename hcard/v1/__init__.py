"""Generated protobuf code for the hcard v1 schema (``spec/hcard/v1/card.proto``).

Do not edit ``card_pb2.py`` or ``card_pb2.pyi`` by hand: regenerate them with
``python scripts/generate_proto.py``; ``tests/card/test_generated_code.py`` fails when they drift.
"""
