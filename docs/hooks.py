"""MkDocs hooks: the project file reference, generated at build time from the models the loader
checks with (through their JSON Schema), so that the page cannot drift from the code; and the
benchmarks' current figures, included from what ``make bench`` last wrote
(``benchmarks/results/NAME.md``, one file per benchmark, in place of ``<!-- bench: NAME -->``)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hycosim.core.schema import project_json_schema  # noqa: E402

MARKER = "<!-- project-reference -->"
RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
BENCH = re.compile(r"<!-- bench: ([a-z_]+) -->")
# The objects of the file, in the order a reader meets them, with the key that holds them.
SECTIONS = [("Project", "the file itself"), ("Node", "nodeLists[]"), ("Port", "input[] and output[] of a node"),
            ("Link", "linkLists[]"), ("CoSimulation", "coSimulation"), ("Event", "events[]"),
            ("Recording", "recording"), ("Security", "security"), ("Tls", "security.tls")]


def _type(spec: dict[str, Any]) -> str:
    if "$ref" in spec:
        return spec["$ref"].rsplit("/", 1)[1]
    if "anyOf" in spec:
        return " or ".join(_type(s) for s in spec["anyOf"])
    if "enum" in spec:
        return " / ".join(json.dumps(v) for v in spec["enum"])
    if spec.get("type") == "array":
        return f"list of {_type(spec.get('items', {}))}" if "prefixItems" not in spec else "pair"
    if spec.get("type") == "object":
        return "object"
    return str(spec.get("type", "any"))


def _limits(spec: dict[str, Any]) -> str:
    parts = []
    for key, sign in (("exclusiveMinimum", ">"), ("minimum", "≥"), ("exclusiveMaximum", "<"), ("maximum", "≤")):
        if key in spec:
            parts.append(f"{sign} {spec[key]:g}")
    if "pattern" in spec:
        parts.append(f"`{spec['pattern']}`")
    for sub in spec.get("anyOf", []):
        limit = _limits(sub)
        if limit:
            parts.append(limit)
    return ", ".join(parts)


def reference() -> str:
    """Markdown tables of every object of the project file: key, type, default, limits."""
    schema = project_json_schema()
    defs = {**schema["$defs"], "Project": schema}
    out = []
    for name, where in SECTIONS:
        spec = defs[name]
        required = set(spec.get("required", []))
        out += [f"### {name}", "", f"*{where}*", "", "| key | type | default | limits |", "|---|---|---|---|"]
        for key, prop in spec["properties"].items():
            default = "required" if key in required else f"`{json.dumps(prop.get('default'))}`"
            out.append(f"| `{key}` | {_type(prop)} | {default} | {_limits(prop)} |")
        out.append("")
    return "\n".join(out)


def figures(name: str) -> str:
    """The table ``make bench`` last wrote for benchmark ``name``; a page that names a benchmark
    with none fails the build, naming the file."""
    path = RESULTS / f"{name}.md"
    if not path.is_file():
        raise ValueError(f"{path}: no figures of benchmarks/{name}.py (make bench writes them)")
    return path.read_text().strip()


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if MARKER in markdown:
        markdown = markdown.replace(MARKER, reference())
    return BENCH.sub(lambda m: figures(m.group(1)), markdown)
