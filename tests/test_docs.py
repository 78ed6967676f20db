"""The documentation: the site builds without a warning, every example marked runnable runs as
written from a fresh folder, every project file in it meets the schema, the README stays short."""

from __future__ import annotations

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


def test_the_site_builds_strictly(tmp_path):
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    reference = (tmp_path / "site" / "project-file" / "index.html").read_text()
    for key in ("checkpointEvery", "drivenVariable", "replay", "factor", "activeIn"):  # generated from the models
        assert f"<code>{key}</code>" in reference, key
    assert "SimulationEnded" in (tmp_path / "site" / "api" / "index.html").read_text()


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
