"""The documentation cannot rot: every shell block is run (or says what checks it), every link resolves,
every parameter and topic of the node is documented, and README stays a guide (about 250 lines).

A fenced shell block must sit right below an HTML comment that starts with ``runnable`` (run here, in
order per file, in a scratch folder beside which ``../shared`` is linked when present) or
``not run by`` (with the reason and what checks it instead).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.ros_harness import domain_id_for_tests

#: runs the documents' commands
pytestmark = pytest.mark.slow

DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), REPO / "benchmarks" / "README.md",
             REPO / "benchmarks" / "HISTORY.md"]
SHELL = {"bash", "sh", "shell", "console"}
FENCE = re.compile(r"^```(\S*)\s*$")
SHARED = REPO.parent / "shared"


def shell_blocks(path: Path) -> list[tuple[int, str, str]]:
    """(line, marker comment, code) of each fenced shell block; marker "" when none precedes it."""
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        match = FENCE.match(lines[i])
        if not match or not match.group(1):
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        if match.group(1) in SHELL:
            marker = ""
            if i > 0 and lines[i - 1].rstrip().endswith("-->"):
                start = max(j for j in range(i) if lines[j].lstrip().startswith("<!--"))
                marker = " ".join(l.strip() for l in lines[start:i]).removeprefix("<!--").removesuffix("-->").strip()
            blocks.append((i + 1, marker, "\n".join(lines[i + 1:end])))
        i = end + 1
    return blocks


def test_every_shell_block_is_run_or_says_what_checks_it():
    unmarked = [f"{p.relative_to(REPO)}:{line}" for p in DOCUMENTS for line, marker, _ in shell_blocks(p)
                if not (marker.startswith("runnable") or marker.startswith("not run by"))]
    assert not unmarked, f"shell blocks without <!-- runnable --> or <!-- not run by ...: why -->: {unmarked}"
    assert sum(marker.startswith("runnable") for p in DOCUMENTS for _, marker, _ in shell_blocks(p)) >= 6


RUNNABLE = [p for p in DOCUMENTS if any(m.startswith("runnable") for _, m, _ in shell_blocks(p))]


@pytest.mark.parametrize("document", RUNNABLE, ids=lambda p: str(p.relative_to(REPO)))
def test_runnable_blocks_run_as_written(document, tmp_path):
    """From the repository's point of view (its files linked into a scratch folder), in order."""
    work = tmp_path / "repo"
    work.mkdir()
    for entry in REPO.iterdir():
        if entry.name not in {".git", ".venv", "build", "install", "log"}:
            (work / entry.name).symlink_to(entry)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}",
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    for line, marker, code in shell_blocks(document):
        if not marker.startswith("runnable"):
            continue
        if "../shared" in marker and not SHARED.is_dir():
            continue  # stated in the marker: these need the authors' data beside the repository
        run = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=work, env=env, capture_output=True,
                             text=True, timeout=300)
        assert run.returncode == 0, (f"{document.relative_to(REPO)}:{line} failed ({run.returncode}):\n{code}\n"
                                     f"--- stdout\n{run.stdout[-2000:]}\n--- stderr\n{run.stderr[-3000:]}")


LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_local_links_resolve(document):
    missing = [target for target in LINK.findall(document.read_text())
               if "://" not in target and not (document.parent / target).exists()]
    assert not missing, f"{document.relative_to(REPO)} links to missing files: {missing}"


def test_the_node_reference_documents_every_parameter_and_topic():
    from ipe_ros.ros.params import all_parameters, reference_columns

    reference = (REPO / "docs" / "node.md").read_text()
    undocumented = [s.name for s in all_parameters() if f"| `{s.name}` |" not in reference]
    assert not undocumented, f"docs/node.md lacks parameters {undocumented}"
    rows = {cells[0]: tuple(cells[:4]) for line in reference.splitlines() if line.startswith("| `")
            for cells in [[c.strip() for c in line.strip().strip("|").split("|")]]}
    stale = [(rows[cols[0]], cols) for cols in map(reference_columns, all_parameters()) if rows[cols[0]] != cols]
    assert not stale, f"docs/node.md's type, default or range differ from the declared ones: {stale}"
    source = (REPO / "ipe_ros" / "ros" / "node.py").read_text()
    topics = set(re.findall(r'create_(?:publisher|subscription|service)\(\s*\w+,\s*"([^"]+)"', source))
    # inputs subscribed once per reliability are listed as (message type, topic, handler)
    topics |= set(re.findall(r'\(\w+, "([^"]+)", self\._on_\w+\)', source))
    assert {"~/scene", "~/fall_probability", "~/fall_fraction", "/diagnostics", "~/predict"} <= topics
    assert not [t for t in topics if f"| `{t}` |" not in reference], topics


def test_readme_is_a_guide_of_about_250_lines():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; move reference to docs/"
    for section in ("## Two commands", "## A five-minute tour", "## The node's interface", "## Scenes",
                    "## What the numbers mean", "## How fast, how accurate", "## Read more"):
        assert section in lines, section
