"""The documents stand alone: every link and every document named in the README, CONTRIBUTING and docs/ is in the
repository (a clone without the project's shared folder beside it holds them all)."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
# a document named in code quotes: a path (`docs/captures.md`) or a project document (`CONTRIBUTING.md`); a run's
# own outputs (`summary.md`) are not documents
NAMED = re.compile(r"`((?:[\w.-]*/)+[\w.-]+\.md|[A-Z][A-Z_]+\.md)`")


def test_every_link_and_named_document_is_in_the_repository():
    missing = []
    for doc in DOCUMENTS:
        text = doc.read_text()
        for target in LINK.findall(text):
            if re.match(r"[a-z]+://", target):
                continue  # a web address
            path = (doc.parent / target).resolve()
            if not path.exists() or ROOT not in path.parents:
                missing.append(f"{doc.relative_to(ROOT)} links {target}")
        for name in NAMED.findall(text):
            here, top = (doc.parent / name).resolve(), (ROOT / name).resolve()
            if not (here.exists() and ROOT in here.parents) and not (top.exists() and ROOT in top.parents):
                missing.append(f"{doc.relative_to(ROOT)} names {name}")
    assert not missing, missing
    assert len(DOCUMENTS) >= 6 and (ROOT / "docs" / "physics.md").is_file()


def test_the_readme_links_the_physics_and_points_nowhere_outside():
    readme = (ROOT / "README.md").read_text()
    assert "](docs/physics.md)" in readme
    for doc in DOCUMENTS:
        assert "DESIGN.md" not in doc.read_text(), doc  # the shared design notes are not in a clone
