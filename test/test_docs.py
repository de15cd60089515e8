"""The README and the Sphinx docs cannot rot: the README stays short and names the two
commands, every parameter `cloth_node --help` prints is in the docs' generated parameter
table, and the docs build with warnings as errors (as `make docs` does)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "doc"
README_LIMIT = 8 * 1024  # bytes: the README says what it is and points at doc/


def help_parameters() -> list[str]:
    """The parameter names `cloth_node --help` prints (one `  name (default ...)` line each)."""
    script = Path(sys.executable).with_name("cloth_node")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "cloth_mg_ros.ros.node"]
    out = subprocess.run([*cmd, "--help"], capture_output=True, text=True, timeout=120,
                         check=True).stdout
    return re.findall(r"^  (\w+) \(default ", out, flags=re.MULTILINE)


def test_readme_is_short_and_has_the_two_commands():
    text = (ROOT / "README.md").read_bytes()
    assert len(text) <= README_LIMIT, f"README.md is {len(text)} bytes (at most {README_LIMIT})"
    for command in ("make demo", "make test"):
        assert command in text.decode(), f"README.md lost `{command}`"
    picture = re.search(r"!\[[^\]]*\]\(([^)]+)\)", text.decode())
    assert picture and (ROOT / picture.group(1)).is_file(), "README.md's picture is missing"


def test_docs_build_without_warnings_and_list_every_parameter(tmp_path):
    """sphinx-build -W on doc/ (the hook in doc/conf.py writes the parameter table), then
    every parameter of `cloth_node --help` must be a row of that table and of the page."""
    pytest.importorskip("sphinx", reason="the test extra installs Sphinx (setup.py)")
    pytest.importorskip("myst_parser", reason="the test extra installs myst-parser")
    build = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(DOC), str(tmp_path / "html")],
        check=False, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, f"the docs build failed:\n{build.stdout}\n{build.stderr}"

    names = help_parameters()
    assert len(names) > 20, f"cloth_node --help listed too few parameters: {names}"
    table = (DOC / "_generated" / "parameters.md").read_text()
    rows = set(re.findall(r"^\| `(\w+)` \|", table, flags=re.MULTILINE))
    missing = [n for n in names if n not in rows]
    assert not missing, f"parameters of cloth_node --help missing from the docs: {missing}"
    page = (tmp_path / "html" / "node.html").read_text()
    absent = [n for n in names if f'<span class="pre">{n}</span>' not in page]
    assert not absent, f"parameters missing from the built node page: {absent}"
