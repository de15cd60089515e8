"""Sphinx configuration of the cloth_mg_ros documentation (MyST markdown pages in doc/).

`make docs` builds it with warnings as errors (sphinx-build -W). The node's parameter table
is not written by hand: on `builder-inited` the hook below writes doc/_generated/parameters.md
from the parameter schema in the code (`parameter_rows`), and node.md includes it, so the
table cannot drift from what `cloth_node --help` prints (test/test_docs.py checks both).
"""

from __future__ import annotations

import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

DOC = Path(__file__).resolve().parent
ROOT = DOC.parent
# The package from this checkout when it is not installed (a plain clone); an installed one
# (make venv, colcon) is the same files.
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

project = "cloth_mg_ros"
author = "cloth_mg_ros maintainers"
copyright = "cloth_mg_ros maintainers, Apache-2.0"
release = ET.parse(ROOT / "package.xml").getroot().findtext("version")
version = release

extensions = ["myst_parser"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "results", "images"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]
html_theme = "alabaster"
html_title = "cloth_mg_ros"
html_static_path: list[str] = []
html_theme_options = {"description": "A ROS 2 cloth simulator with a physically faithful "
                                     "multigrid", "fixed_sidebar": True}

GENERATED = DOC / "_generated"
PARAMETER_PAGE = GENERATED / "parameters.md"
_TYPES = {str: "string", bool: "bool", int: "integer", float: "double"}


def parameter_rows() -> list[dict]:
    """Every parameter `cloth_node --help` lists, with the walking scene's defaults.

    One dict per parameter: name, default, type, range (its unit and the values it takes),
    runtime (True: may be set while the node runs) and meaning. The one place the docs
    import the parameter schema: `cloth_mg_ros.config.schema` (parameter_table,
    scene_defaults, usage_text), or `cloth_mg_ros.ros.parameters` before the schema moved
    there; drop the fallback once it has.
    """
    try:  # the one parameter schema, where the package keeps it now
        from cloth_mg_ros.config.schema import parameter_table, scene_defaults, usage_text
    except ImportError:  # before it moved there
        from cloth_mg_ros.ros.parameters import parameter_table, scene_defaults, usage_text

    body, defaults = scene_defaults("walking")
    rows = []
    for name, spec in parameter_table(body, defaults).items():
        if spec.default == "auto":  # a number or 'auto' (particles, tolerance)
            kind = ("double" if spec.float_range else "integer") + " or auto"
        else:
            kind = _TYPES[type(spec.default)]
        if spec.constraints:
            span = spec.constraints.replace("'auto'", "auto")
        elif spec.int_range is not None:
            span = f"{spec.int_range[0]}..{spec.int_range[1]}"
        elif spec.float_range is not None:
            span = f"{spec.float_range[0]:g}..{spec.float_range[1]:g}"
        else:
            span = ""
        numeric = isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool)
        unit = _unit(spec.description) if numeric else ""
        rows.append({"name": name, "default": _show(spec.default), "type": kind,
                     "range": f"{unit}; {span}" if unit and span else unit or span,
                     "runtime": not spec.read_only, "meaning": spec.description})
    # Parameters --help lists that the table does not declare (ROS 2's own use_sim_time).
    known = {row["name"] for row in rows}
    lines = usage_text().splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"^  (\w+) \(default (.*)\)$", line)
        if m and m.group(1) not in known:
            meaning = []
            for more in lines[i + 1:]:
                if not more.startswith("      "):
                    break
                meaning.append(more.strip())
            rows.append({"name": m.group(1), "default": m.group(2).strip("'"), "type": "bool"
                         if m.group(2) in ("True", "False") else "", "range": "",
                         "runtime": False, "meaning": " ".join(meaning)})
    return rows


def _unit(description: str) -> str:
    """The unit a description names (', m' at the end of a clause, 's between ...')."""
    m = re.search(r", (m|s|Hz)\b(?!\w)", description) or re.match(r"^(s) ", description)
    if m:
        return m.group(1)
    return "s" if description.startswith("seconds ") else ""


def _show(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def parameter_markdown(rows: list[dict]) -> str:
    """The MyST table node.md includes."""
    out = ["| parameter | type | default | unit; values | set | meaning |",
           "|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| `{r['name']}` | {r['type']} | `{_cell(r['default'])}` | "
                   f"{_cell(r['range'])} | {'run time' if r['runtime'] else 'start'} | "
                   f"{_cell(r['meaning'])} |")
    return ("<!-- Generated by doc/conf.py (parameter_rows) at each build: do not edit. -->\n\n"
            + "\n".join(out) + "\n")


def write_parameter_page(app=None) -> Path:
    """Write doc/_generated/parameters.md (only when it changed, so Sphinx does not rebuild
    node.md for nothing)."""
    text = parameter_markdown(parameter_rows())
    GENERATED.mkdir(exist_ok=True)
    if not PARAMETER_PAGE.exists() or PARAMETER_PAGE.read_text() != text:
        PARAMETER_PAGE.write_text(text)
    return PARAMETER_PAGE


def setup(app):
    app.connect("builder-inited", write_parameter_page)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
