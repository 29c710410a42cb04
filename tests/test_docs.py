"""The front page and the docs: a README within its budget, no outside names, no dead links."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: What a user of the repository does not have: issue numbers, design cards, folders outside it.
OUTSIDE = re.compile(r"\bP\d{1,2}\b|\bissue P\d|design card|\.\./shared|/work/")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def test_the_readme_is_a_front_page_within_its_budget() -> None:
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    for section in ("## Quick start", "## How learning works", "## Commands",
                    "## Your own vehicle", "## The paper", "## Documentation"):  # fmt: skip
        assert section in text, section
    for command in ("make fly", "make fly-mocap", "make test"):
        assert command in text, command
    assert "Meraglia and M. Lovera" in text and "Smoother-based Iterative Learning Control" in text


def test_no_page_names_anything_outside_the_repository() -> None:
    for page in PAGES:
        for n, line in enumerate(page.read_text().splitlines(), 1):
            assert not OUTSIDE.search(line), f"{page.relative_to(ROOT)}:{n}: {line.strip()}"


def test_every_relative_link_resolves() -> None:
    dead = []
    for page in PAGES:
        for target in LINK.findall(page.read_text()):
            if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            if not file.exists():
                dead.append(f"{page.relative_to(ROOT)}: {target}")
            elif anchor and file.suffix == ".md":
                headings = re.findall(r"^#+ (.+)$", file.read_text(), flags=re.M)
                if anchor not in {_slug(h) for h in headings}:
                    dead.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert not dead, "\n".join(dead)


def test_every_docs_page_says_what_it_is_for() -> None:
    generated = {"bad-inputs.md"}  # written by tools/bad_inputs.py
    for page in (ROOT / "docs").glob("*.md"):
        if page.name in generated:
            continue
        lines = [line for line in page.read_text().splitlines() if line.strip()]
        assert lines[0].startswith("# "), page.name
        assert len(lines) > 1 and not lines[1].startswith("#"), page.name


#: A profile, trajectory or mock settings named on a command line of a page.
NAMED = re.compile(r"--(profile|trajectory|mock-config)[ =]([^\s`)|,;'\"]+)")
#: A file of the repository named by its path.
REPO_PATH = re.compile(
    r"(?<![\w/.<-])((?:tools|benchmarks|examples|profiles|trajectories|tests|docs|gcs)/"
    r"[\w./-]+\.(?:py|yaml|md|csv|json|txt))"
)
#: Placeholders for the reader's own file: "my-loop.yaml", "profiles/mine.yaml".
OWN = re.compile(r"(^|/)(my-|mine\b)")


def _created_by(text: str, name: str) -> bool:
    """Whether the page writes ``name`` before using it (``--out``, ``>``, ``open(.., 'w')``)."""
    n = re.escape(name)
    return bool(
        re.search(rf"--out[ =]{n}(\s|$)|>\s*{n}(\s|$)|open\(['\"]{n}['\"],\s*['\"]w", text, re.M)
    )


def test_every_profile_and_trajectory_a_page_names_is_shipped_or_made_there() -> None:
    from gcs.io.paths import packaged_names

    shipped = {
        "profile": set(packaged_names("profile")),
        "trajectory": set(packaged_names("trajectory")),
        "mock-config": set(packaged_names("profile")),
    }
    dead = []
    for page in [ROOT / "logs" / "README.md", *PAGES]:
        if page.name == "bad-inputs.md":  # the catalogue names bad inputs on purpose
            continue
        text = page.read_text()
        for option, value in NAMED.findall(text):
            value = value.rstrip(".:")
            name = value[:-5] if value.endswith(".yaml") else value
            if name in shipped[option] or (ROOT / value).is_file() or OWN.search(value):
                continue
            if not _created_by(text, value):
                dead.append(f"{page.relative_to(ROOT)}: --{option} {value}")
        for path in REPO_PATH.findall(text):
            if not (ROOT / path).exists() and not _created_by(text, path) and not OWN.search(path):
                dead.append(f"{page.relative_to(ROOT)}: {path}")
    assert not dead, "\n".join(dead)
