"""Every relative link in the README, docs/, BUILD_NOTES.md and the results READMEs resolves to a file
or folder of the repository (anchors are not checked, only the file they are in)."""
import re
from pathlib import Path

import pytest

from tests.paths import ROOT

# [text](target) and ![alt](target); the target ends at whitespace or ')' (an optional "title" after it)
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE = re.compile(r"`[^`\n]*`")


def documents() -> list[Path]:
    files = [ROOT / "README.md", ROOT / "BUILD_NOTES.md", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "results").rglob("README.md"))]
    return [f for f in files if f.is_file()]


def relative_links(text: str) -> list[str]:
    """The relative link targets of a Markdown text, outside code blocks and code spans."""
    text = CODE.sub("", FENCE.sub("", text))
    targets = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue  # http:, https:, mailto:, ... and anchors in the same page
        targets.append(target)
    return targets


def test_the_documents_are_found_and_linked():
    names = {f.relative_to(ROOT).as_posix() for f in documents()}
    assert {"README.md", "BUILD_NOTES.md", "docs/reproducing-the-paper.md", "results/README.md",
            "results/methods/README.md", "results/scaling/README.md"} <= names
    readme = (ROOT / "README.md").read_text()
    for page in sorted((ROOT / "docs").glob("*.md")):  # every docs page is listed in the README
        assert f"(docs/{page.name})" in readme, f"docs/{page.name} is not linked from README.md"
    assert relative_links("[a](b.md#x) ![c](d.png) [e](https://x.org) [f](#g) `[h](i.md)`") == ["b.md#x", "d.png"]


@pytest.mark.parametrize("document", documents(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_resolves(document):
    missing = []
    for target in relative_links(document.read_text()):
        path = target.split("#", 1)[0]
        if path and not (document.parent / path).exists():
            missing.append(target)
    assert not missing, f"{document.relative_to(ROOT)}: links to missing files: {', '.join(missing)}"
