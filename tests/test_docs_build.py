"""The docs check can fail: ``mkdocs build --strict`` (the README's and CI's build, without
``-q``) refuses a page outside the nav and a link to no page."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _test_command() -> str:
    readme = (ROOT / "README.md").read_text()
    return re.search(r"<!-- test-command -->\n```bash\n(.*?)\n```", readme, re.S).group(1)


def test_the_docs_build_shows_its_warnings():
    """``-q`` hides the warnings ``--strict`` counts: CI's build must not have it."""
    build = next(part for part in _test_command().split("&&") if "mkdocs build" in part)
    assert "--strict" in build and " -q" not in build


def test_an_orphan_page_or_a_broken_link_fails_the_build(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    copy = tmp_path / "repo"
    copy.mkdir()
    shutil.copy(ROOT / "mkdocs.yml", copy)
    for name in ("docs", "abco_envs", "abco_data", "abco_train", "README.md", "CHANGELOG.md"):
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
        elif source.exists():
            shutil.copy(source, copy / name)
    (copy / "docs" / "orphan-page.md").write_text("# In no nav\n")
    index = copy / "docs" / "index.md"
    index.write_text(index.read_text() + "\n[gone](no-such-page.md)\n")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d",
                           str(tmp_path / "site")], cwd=copy, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, timeout=600)
    log = done.stdout + done.stderr
    assert done.returncode != 0, log[-2000:]
    assert "orphan-page.md" in log and "no-such-page.md" in log, log[-2000:]
