"""The documentation: the site builds without a warning, every example marked runnable runs as
written from a fresh folder, every project file in it meets the schema, the README stays short."""

from __future__ import annotations

import html
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from hycosim.core.schema import project_json_schema
from tests.helpers import REPO

DOCS = REPO / "docs"
# <!-- file: NAME --> before a fenced block: write the block to NAME; <!-- shell --> before a
# console block: run its "$ " lines, in order, as one bash script (a failing one fails it).
_BLOCK = re.compile(r"<!-- (file: (?P<name>[\w.\-]+)|shell) -->\n```[a-z]*\n(?P<body>.*?)```", re.S)
PAGES = sorted(p for p in DOCS.glob("*.md") if _BLOCK.search(p.read_text()))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The manual built as a site, strictly (a warning fails it)."""
    out = tmp_path_factory.mktemp("docs") / "site"
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    return out


def test_the_site_builds_strictly(site):
    reference = (site / "project-reference" / "index.html").read_text()
    for key in ("checkpointEvery", "drivenVariable", "replay", "factor", "activeIn"):  # generated from the models
        assert f"<code>{key}</code>" in reference, key
    assert "SimulationEnded" in (site / "api" / "index.html").read_text()


_ARTICLE = re.compile(r'<article class="md-content__inner md-typeset">(.*?)</article>', re.S)
_HREF = re.compile(r'href="([^"]*)"')
_IDS = re.compile(r'id="([^"]+)"')


def _article(page: Path) -> str:
    found = _ARTICLE.search(page.read_text())
    assert found, page
    return found.group(1)


def _target(site: Path, page: Path, href: str) -> tuple[Path, str]:
    """The built file and the anchor an href of ``page`` leads to."""
    path, _, anchor = href.partition("#")
    target = (page.parent / path).resolve() if path else page
    if target.is_dir() or not target.suffix:
        target = target / "index.html"
    return target, anchor


def test_every_cross_reference_of_the_manual_leads_to_a_page_and_a_heading_that_exist(site):
    """mkdocs --strict checks that a linked page exists; this checks the heading (#anchor) too,
    in the built site, for every link of every page's text."""
    broken = []
    for page in sorted(site.rglob("*.html")):
        if page.name == "404.html" or "assets" in page.parts or "search" in page.parts:
            continue
        for href in _HREF.findall(_article(page)):
            if href.startswith(("http://", "https://", "mailto:")) or href.endswith((".png", ".svg")):
                continue
            target, anchor = _target(site, page, href)
            if not target.exists():
                broken.append(f"{page.relative_to(site)}: {href} (no page)")
            elif anchor and anchor not in _IDS.findall(target.read_text()):
                broken.append(f"{page.relative_to(site)}: {href} (no heading #{anchor})")
    assert not broken, "\n".join(broken)


def test_every_page_is_a_manual_page_with_headings_and_at_most_12000_characters():
    for page in sorted(DOCS.glob("*.md")):
        text = page.read_text()
        assert len(text) <= 12_000, f"{page.name} has {len(text)} characters: split it"
        assert re.search(r"(?m)^## ", text), f"{page.name} has no ## heading to link to"
        assert "this session" not in text, f"{page.name} reads as a diary: history goes to CHANGELOG.md"


# The five questions a newcomer asks first, each answered within one link of the README: the
# link's words, and what the section it leads to (in the built site) must say.
NEWCOMER = [
    ("install", "docs/install.md", ["Python 3.11", "pip install hycosim", "make run"]),
    ("couple two FMUs of your own", "docs/getting-started.md#1-two-fmus-coupled", ["fmu", "hycosim run"]),
    ("write a Python node with rollback", "docs/nodes.md#rollback-and-checkpoints", ["get_state", "set_state", "checkpoints_taken"]),
    ("run a node on another host", "docs/getting-started.md#4-a-node-from-a-second-host", ["hycosim node", "--connect"]),
    ("what exit code 3 means", "docs/troubleshooting.md#exit-codes", ["<td>3</td>", "the run failed"]),
]


@pytest.mark.parametrize("question, link, says", NEWCOMER, ids=[q for q, *_ in NEWCOMER])
def test_a_newcomers_question_is_answered_one_link_from_the_readme(site, question, link, says):
    readme = (REPO / "README.md").read_text()
    assert f"]({link})" in readme, f"the README has no link to {link} ({question})"
    path, _, anchor = link.removeprefix("docs/").partition("#")
    page = site / path.removesuffix(".md") / "index.html" if path != "index.md" else site / "index.html"
    article = _article(page)
    if anchor:
        start = article.index(f'id="{anchor}"')
        following = re.search(r"<h2 ", article[start + 1:])
        article = article[start: start + 1 + following.start()] if following else article[start:]
    text = html.unescape(re.sub(r"<[^>]+>", "", article))  # highlighted code is split into spans
    for words in says:
        assert words in article or words in text, f"{link} does not say {words!r} ({question})"


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_the_examples_of_a_page_run_as_written(tmp_path, page):
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}", PYTHONPATH=str(REPO))
    validator = Draft202012Validator(project_json_schema())
    for block in _BLOCK.finditer(page.read_text()):
        if block["name"]:
            (tmp_path / block["name"]).write_text(block["body"])
            if block["name"].endswith(".json"):
                errors = [e.message for e in validator.iter_errors(json.loads(block["body"]))]
                assert not errors, (block["name"], errors)
            continue
        script = "\n".join(line[2:] for line in block["body"].splitlines() if line.startswith("$ "))
        res = subprocess.run(["bash", "-e", "-c", script], capture_output=True, text=True, cwd=tmp_path, env=env,
                             timeout=300)
        assert res.returncode == 0, f"{page.name}:\n{script}\n--- exit {res.returncode}\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"


def test_the_readme_is_short_and_its_links_lead_somewhere():
    readme = (REPO / "README.md").read_text()
    assert len(readme) <= 8000, f"README.md has {len(readme)} characters; reference material goes in docs/"
    links = re.findall(r"\]\(([^)#]+)", readme)
    assert any(link.startswith("docs/") for link in links)
    for link in links:
        if not link.startswith("http"):
            assert (REPO / link).exists(), link
