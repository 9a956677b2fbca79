"""Rule identifiers of spec/ (spec/README.md 1.3): each defined once, under a prefix of its own
document, and every one the repository cites is defined; and the repository refers to no
document or tracker outside it.

The scanners are plain functions of text so that the tests below can show each one catching a
planted mistake.
"""

from __future__ import annotations

import functools
import re
from collections import Counter
from pathlib import Path

from tests.helpers.repository import REPO

SPEC = REPO / "spec"
THIS_FILE = Path(__file__).resolve()

TEXT_SUFFIXES = {
    ".py", ".md", ".proto", ".toml", ".txt", ".cfg", ".ini", ".yml", ".yaml", ".json", ".sh",
    ".csv", ".rst",
}
"""Files that hold prose or code (the vectors' binary cards, NPZ renders and images do not)."""
SKIPPED_DIRS = {".git", "__pycache__", "build", "dist", ".venv", "venv", ".mypy_cache",
                ".pytest_cache", ".ruff_cache", ".hypothesis", "node_modules"}
"""Folders of tools' caches and build output, not of the repository (with ``*.egg-info``)."""
NOT_RULES = {"U8", "U16", "U32", "Q0", "C0"}
"""Words of an identifier's shape that are not identifiers (spec/README.md 1.3)."""

_ID = r"[A-Z]{1,2}(?:0|[1-9][0-9]*)[a-z]?"
_BOLD_LEAD = re.compile(rf"^(?:- )?\*\*({_ID})\b")
_TABLE_CELL = re.compile(rf"^\|\s*({_ID})\s*\|")
_NOQA = re.compile(r"noqa:[A-Z0-9, ]*")
_RULE_WORD = re.compile(r"\b[Rr]ules?\s+([A-Z][A-Za-z]*-?[A-Za-z0-9]*)")


@functools.cache
def repository_files(root: Path = REPO) -> tuple[Path, ...]:
    """The text files of the repository, this test excepted (it plants mistakes on purpose);
    listed once per run and root."""
    found = []
    for path in root.rglob("*"):
        parts = set(path.relative_to(root).parts)
        if parts & SKIPPED_DIRS or any(p.endswith(".egg-info") for p in parts):
            continue
        if path.is_file() and path.resolve() != THIS_FILE and (
            path.suffix in TEXT_SUFFIXES or path.name == "run"
        ):
            found.append(path)
    return tuple(sorted(found))


def prefix_table(readme_text: str) -> dict[str, str]:
    """Prefix -> the document that owns it, from the table of spec/README.md 1.3 (a section
    number in the last column means README.md itself)."""
    owners: dict[str, str] = {}
    lines = readme_text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| Prefix |"))
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        prefixes, _, where = (cell.strip() for cell in line.strip("|").split("|"))
        document = where.strip("`") if where.startswith("`") else "README.md"
        for prefix in prefixes.split(","):
            assert prefix.strip() not in owners, f"prefix {prefix.strip()} listed twice"
            owners[prefix.strip()] = document
    return owners


def definitions(text: str) -> list[str]:
    """Identifiers a spec document defines: a bold lead opening a paragraph or list item, or
    the first cell of a table row (spec/README.md 1.3), in order, repeats kept."""
    found = []
    previous = ""
    for line in text.splitlines():
        bold = _BOLD_LEAD.match(line)
        if bold and (not previous.strip() or line.startswith("- ")):
            found.append(bold.group(1))
        cell = _TABLE_CELL.match(line)
        if cell:
            found.append(cell.group(1))
        previous = line
    return found


def citation_pattern(prefixes: set[str]) -> re.Pattern[str]:
    """A whole word made of one of ``prefixes``, a number and an optional letter."""
    alternatives = "|".join(sorted(prefixes, key=len, reverse=True))
    return re.compile(rf"\b(?:{alternatives})(?:0|[1-9][0-9]*)[a-z]?\b")


def bad_citations(text: str, defined: set[str], prefixes: set[str]) -> list[tuple[int, str]]:
    """(line, word) of every citation in ``text`` that names no defined rule: identifiers of a
    registered prefix, and whatever follows "rule"/"rules"."""
    pattern = citation_pattern(prefixes)
    bad = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = _NOQA.sub("", line)  # linter codes (F401) are not rules
        words = set(pattern.findall(line)) | {m.group(1) for m in _RULE_WORD.finditer(line)}
        # after "rule", a capitalised word without digit or hyphen is prose ("Rule Of")
        bad += [(number, word) for word in sorted(words)
                if word not in defined and word not in NOT_RULES and re.search(r"[0-9-]", word)]
    return bad


_OUTSIDE = re.compile(
    r"DESIGN\.md|/work/|000_4ba21c99c01f7c36"
    r"|\bissue(?:'s)?\b(?!\s+(?:a|an|the|it|them|commands?|requests?)\b)",
    re.IGNORECASE,
)
"""References a reader of the repository cannot follow: the project's design note, files of
the machine it was written on, the thesis text's local file, and the issue tracker (the noun,
alone or with a number; the verb, "hosts issue a STOP", is fine)."""

DESIGN_NOTE = "DESIGN" + ".md"
TRACKER_ENTRY = "issue" + " 12"
"""Outside references the planted-mistakes test writes to its temporary file; assembled here so
that this file (excepted from the scans) does not itself name a document or a tracker entry."""


def outside_references(text: str) -> list[tuple[int, str]]:
    """(line, text) of every reference in ``text`` to a document or tracker outside the
    repository."""
    return [(n, m.group(0)) for n, line in enumerate(text.splitlines(), start=1)
            for m in _OUTSIDE.finditer(line)]


def spec_documents() -> dict[str, str]:
    """Every spec document by its path under spec/ (``README.md``, ``interchange/hjif.md``)."""
    return {path.relative_to(SPEC).as_posix(): path.read_text(encoding="utf-8")
            for path in sorted(SPEC.rglob("*.md"))}


@functools.cache
def defined_rules() -> tuple[dict[str, list[str]], dict[str, str]]:
    """Identifier -> documents defining it; prefix -> owning document (read once per run; the
    callers do not modify them)."""
    documents = spec_documents()
    owners = prefix_table(documents["README.md"])
    where: dict[str, list[str]] = {}
    for name, text in documents.items():
        for rule in definitions(text):
            where.setdefault(rule, []).append(name)
    return where, owners


def test_every_rule_is_defined_once_under_a_prefix_of_its_document():
    where, owners = defined_rules()
    assert len(where) >= 192  # every document's rules were found (192 when written)
    # every document that owns a prefix defines rules, and only those do
    assert set(owners.values()) == {document for docs in where.values() for document in docs}
    twice = {rule: docs for rule, docs in where.items() if len(docs) > 1}
    assert not twice, f"defined more than once: {twice}"
    for rule, (document,) in where.items():
        prefix = re.match(r"[A-Z]+", rule).group(0)
        assert owners.get(prefix) == document, (
            f"{rule} is defined in {document}, but prefix {prefix} belongs to {owners.get(prefix)}"
        )


def test_every_cited_rule_exists():
    where, owners = defined_rules()
    problems = []
    for path in repository_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        problems += [f"{path.relative_to(REPO)}:{line}: {word}"
                     for line, word in bad_citations(text, set(where), set(owners))]
    assert not problems, "citations of rules that spec/ does not define:\n" + "\n".join(problems)


def test_no_reference_outside_the_repository():
    problems = []
    for path in repository_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        problems += [f"{path.relative_to(REPO)}:{line}: {found}"
                     for line, found in outside_references(text)]
    assert not problems, "references outside the repository:\n" + "\n".join(problems)


def test_the_scanners_catch_planted_mistakes(tmp_path):
    where, owners = defined_rules()
    defined, prefixes = set(where), set(owners)
    planted = tmp_path / "planted.py"
    planted.write_text(
        '"""Velocity estimate (rule R4), split (spec rule R-split), padding (rule P7),\n'
        f"frames R3-R14, stroke MS9, report QP3; see {DESIGN_NOTE} and {TRACKER_ENTRY}.\n"
        'U16 is a type and hosts issue a STOP."""\n',
        encoding="utf-8",
    )
    assert planted in repository_files(tmp_path)
    text = planted.read_text(encoding="utf-8")
    assert bad_citations(text, defined, prefixes) == [
        (1, "P7"), (1, "R-split"), (2, "MS9"), (2, "R14"),
    ]
    assert outside_references(text) == [(2, DESIGN_NOTE), (2, TRACKER_ENTRY.split()[0])]
    assert outside_references("the issue's goal; /work/shared/x.txt") == [
        (1, "issue's"), (1, "/work/")
    ]


def test_definitions_follow_the_documented_forms():
    text = (
        "**R4 (sample state).** For each sample\n"
        "- **K1 (samples).** All samples\n"
        "| G1 | `surface.width_mm` | finite |\n"
        "\n**Detail of G4.** With\n"
        "text that wraps and\n**L3** `e_drop` is a citation mid-paragraph\n"
    )
    assert definitions(text) == ["R4", "K1", "G1"]
    # O3 is defined by its table row (conformance.md section 0) and bolded again mid-paragraph
    # in section 4.8 ("`released-by-stop` (**O3**)"): a citation, not a second definition.
    assert Counter(definitions(spec_documents()["conformance.md"]))["O3"] == 1
