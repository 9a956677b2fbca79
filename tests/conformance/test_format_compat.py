"""Check ``format.compat`` (spec/conformance.md Q4b; README V3, V4, F2, F4): the reference
reader and writer pass every case; readers and writers with one fault each fail the case of
that fault, by the count of what they lost; the wire reader agrees with protobuf's own."""

from __future__ import annotations

import gzip
import json

import pytest
from google.protobuf import descriptor_pb2, json_format
from google.protobuf.message import Message
from google.protobuf.unknown_fields import UnknownFieldSet

from hcard import card_io
from hcard.card_io import parse_card
from hcard.v1 import card_pb2 as pb
from hcard_conformance import format_compat
from hcard_conformance.context import Context
from hcard_conformance.result import CheckResult
from hcard_conformance.runner import run_suite
from hcard_conformance.vectors import load_manifest
from hcard_conformance.wire_fields import WireError, WireField, unknown_fields
from tests.helpers.repository import REPO

VECTORS = REPO / "spec" / "vectors"
MANIFEST = load_manifest(VECTORS)
CASES = ["unknown-fields.hcard", "unknown-fields.json", "binary-named.json",
         "json-named.hcard", "json-writer"]


def _run() -> dict[str, CheckResult]:
    report = run_suite(Context.for_driver("sim://"), ("format",), select=("format.compat",))
    return {r.case: r for r in report.results}


def test_the_reference_reader_and_writer_pass_every_case() -> None:
    results = _run()
    assert list(results) == CASES
    for case, r in results.items():
        assert r.outcome == "PASS" and r.value == 0.0, (case, r.detail)
    assert "5 of 5 unknown fields kept, minor 9" in results["unknown-fields.hcard"].detail
    assert "12 cards written" in results["json-writer"].detail


def test_a_reader_that_drops_unknown_fields_loses_all_five(monkeypatch) -> None:
    """A converter that rebuilds the card from the fields it knows (V3 broken): each of the
    five listed fields counts one; reading alone (the JSON case) still passes."""
    def forgetful(data: bytes, *, source: object = None, check: bool = True) -> pb.Card:
        card = parse_card(data, source=source, check=check)  # type: ignore[arg-type]
        card.DiscardUnknownFields()
        return card

    monkeypatch.setattr(format_compat, "parse_card", forgetful)
    results = _run()
    lost = results["unknown-fields.hcard"]
    assert lost.outcome == "FAIL" and lost.value == 5.0
    assert "re-written without unknown field 900 of the card (V3)" in lost.detail
    assert "re-written without unknown field 903 of textures[1] (V3)" in lost.detail
    assert results["unknown-fields.json"].outcome == "PASS"


def test_a_writer_that_lowers_the_minor_fails(monkeypatch) -> None:
    """A writer that stamps its own version 1.0 on a 1.9 card it re-writes (V3: MUST NOT
    lower the minor of a card with unknown fields)."""
    def stamping(card: pb.Card) -> bytes:
        copy = pb.Card()
        copy.CopyFrom(card)
        copy.version.minor = 0
        return card_io.to_bytes(copy)

    monkeypatch.setattr(format_compat, "to_bytes", stamping)
    result = _run()["unknown-fields.hcard"]
    assert result.outcome == "FAIL"
    assert "re-written as minor 0, read as 9" in result.detail


def test_a_reader_that_trusts_the_file_name_fails_both_misnamed_files(monkeypatch) -> None:
    """F4: the extension is a hint; a reader that picks the form from it (and reads JSON with
    protobuf's strict parser) rejects both misnamed files, and the JSON with unknown keys."""
    def by_name(data: bytes, *, source: object = None, check: bool = True) -> pb.Card:
        if str(source).endswith(".json"):
            return json_format.Parse(data.decode("utf-8"), pb.Card())
        return pb.Card.FromString(data)

    monkeypatch.setattr(format_compat, "parse_card", by_name)
    results = _run()
    for case in ("binary-named.json", "json-named.hcard"):
        assert results[case].outcome == "FAIL" and results[case].value == 1.0
        assert "the reader raised" in results[case].detail
    # protobuf's strict JSON parser also refuses unknown keys: V4 broken as well
    assert results["unknown-fields.json"].outcome == "FAIL"
    assert "ParseError" in results["unknown-fields.json"].detail


def _writer_faults(text: str, name: str = "checkerboard") -> list[str]:
    card = MANIFEST.card(name).load_card()
    return format_compat.json_writer_problems(json.loads(text), card)


def test_the_json_writer_rules_count_each_fault() -> None:
    """F2 judged on JSON from protobuf's own writer, configured four ways."""
    card = MANIFEST.card("checkerboard").load_card()
    assert _writer_faults(card_io.to_json(card)) == []
    camel = json_format.MessageToJson(card, always_print_fields_with_no_presence=True)
    faults = _writer_faults(camel)
    assert faults and all("not a proto field name (a lowerCamelCase JSON name)" in f
                          or "left out, but not zero" in f for f in faults)
    assert any(f.startswith("taxtelWidthMm") or ".taxtelWidthMm" in f or "grid" in f
               for f in faults)
    numbers = json_format.MessageToJson(card, preserving_proto_field_name=True,
                                        use_integers_for_enums=True,
                                        always_print_fields_with_no_presence=True)
    enum_faults = [f for f in _writer_faults(numbers) if "enum written as" in f]
    components = sum(len(t.components) for t in card.textures)
    assert len(enum_faults) == 2 * len(card.textures) + 2 * components  # channel, locking;
    # domain, channel
    obj = json.loads(card_io.to_json(card))
    obj["surface"]["width_mm"] = float(f"{card.surface.width_mm + 1e-7:.6g}") + 1e-9
    rounded = _writer_faults(json.dumps(obj))
    assert len(rounded) == 1 and "surface.width_mm" in rounded[0]
    del obj["surface"]
    assert _writer_faults(json.dumps(obj)) == ["surface: left out, but not zero"]


def test_the_vectors_hold_what_the_manifest_lists() -> None:
    """The binary vector's unknown fields, found by protobuf's own runtime, are the five the
    manifest lists at the depths it names; the JSON vector carries keys 1.0 does not define
    at four depths."""
    entry = next(c for c in MANIFEST.compat if c.case == "unknown-fields.hcard")
    data = entry.file.read_bytes()
    card = pb.Card.FromString(data)
    found = {("", u.field_number) for u in UnknownFieldSet(card)}
    found |= {("metadata", u.field_number) for u in UnknownFieldSet(card.metadata)}
    found |= {("textures[1]", u.field_number) for u in UnknownFieldSet(card.textures[1])}
    found |= {("textures[1].components[0]", u.field_number)
              for u in UnknownFieldSet(card.textures[1].components[0])}
    assert found == {(u["path"], u["number"]) for u in entry.unknown}
    assert len(found) == 5 and card.version.minor == 9
    assert data[:3] == bytes([0xA0, 0x38, 0xAC])  # field 900 (varint 300) before the version
    text = json.loads((VECTORS / "compat" / "unknown-fields.json").read_text("utf-8"))
    known = {f.name for f in pb.Card.DESCRIPTOR.fields}
    assert sorted(set(text) - known) == ["extensions", "surface_finish"]
    assert text["textures"][1]["roughnessHint"] is True
    assert "envelope" in text["textures"][1]["components"][0]


def test_the_wire_reader_on_bytes_from_the_encoding_guide() -> None:
    """Field 1 = 150 is ``08 96 01`` (protobuf encoding guide); FormatVersion defines 1 and 2,
    so field 3 is unknown wherever it sits; truncated bytes are an error."""
    version = pb.FormatVersion.DESCRIPTOR
    assert unknown_fields(bytes([0x08, 0x96, 0x01]), version) == []
    assert unknown_fields(bytes([0x18, 0x96, 0x01, 0x08, 0x01]), version) == [
        WireField("", 3, 0, bytes([0x96, 0x01]))]
    nested = bytes([0x0A, 0x02, 0x28, 0x07])  # Card.version = {field 5: 7}
    assert unknown_fields(nested, pb.Card.DESCRIPTOR) == [WireField("version", 5, 0, b"\x07")]
    for broken in (bytes([0x08, 0x96]), bytes([0x0A, 0x05, 0x08]), bytes([0x0B])):
        with pytest.raises(WireError):
            unknown_fields(broken, pb.Card.DESCRIPTOR)


PUBLIC_PROTOBUF = REPO / "tests" / "data" / "public" / "protobuf" / "testprotos.pb.gz"


def _runtime_unknown(message: Message, path: str = "") -> list[tuple[str, int]]:
    """(path, number) of every unknown field protobuf's runtime kept in ``message``."""
    found = [(path, u.field_number) for u in UnknownFieldSet(message)]
    for field, value in message.ListFields():
        if field.type != field.TYPE_MESSAGE:
            continue
        where = f"{path}.{field.name}" if path else field.name
        items = enumerate(value) if field.is_repeated else [(None, value)]
        for index, item in items:
            found += _runtime_unknown(item, where if index is None else f"{where}[{index}]")
    return found


def test_the_wire_reader_agrees_with_protobuf_on_a_file_protoc_wrote() -> None:
    """The protobuf project's own FileDescriptorSet (41 files; tests/data/public/protobuf):
    its custom options and editions features are fields ``descriptor_pb2`` does not define.
    The wire reader finds exactly the unknown fields, at exactly the paths, that protobuf's
    runtime keeps (89 of them in that file)."""
    data = gzip.decompress(PUBLIC_PROTOBUF.read_bytes())
    descriptors = descriptor_pb2.FileDescriptorSet.FromString(data)
    assert len(descriptors.file) == 41
    runtime = sorted(_runtime_unknown(descriptors))
    assert len(runtime) == 89
    found = unknown_fields(data, descriptor_pb2.FileDescriptorSet.DESCRIPTOR)
    assert sorted((f.path, f.number) for f in found) == runtime


def test_hostile_wire_bytes_are_errors_not_hangs() -> None:
    """A length prefix of 2 GiB on 6 bytes, a varint of 11 continuation bytes, a group tag and
    field number 0 are each a WireError at once."""
    for hostile in (bytes([0x2A, 0x80, 0x80, 0x80, 0x80, 0x08, 0x00]),  # textures, 2 GiB
                    bytes([0x08]) + b"\xff" * 11,
                    bytes([0x2B, 0x2C]),  # field 5 as a start and end group
                    bytes([0x00, 0x01])):
        with pytest.raises(WireError):
            unknown_fields(hostile, pb.Card.DESCRIPTOR)
