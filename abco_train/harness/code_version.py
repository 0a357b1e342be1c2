"""Which code made a result: the package version and a digest of the code that trains and
evaluates.

Every ``final.json`` records :func:`code_version`, and ``abco report`` flags a record whose
``source`` differs from the code it runs with: its numbers may not be what this code gives.

The digest covers the syntax trees of the modules that decide a run's numbers: all of
``abco_envs`` and ``abco_data`` and ``abco_train`` except the report, the grid runner and the
command lines (:data:`EXCLUDED`). Docstrings and comments are left out (a trees' dump has
neither), so editing documentation does not flag results; any change to code does, even one
that happens not to change the numbers: re-run, or read the flagged records knowing that.

Example:
    >>> version = code_version()
    >>> sorted(version), len(version["source"])
    (['source', 'version'], 16)
"""

from __future__ import annotations

import ast
import hashlib
from functools import lru_cache
from pathlib import Path

__all__ = ["code_version", "package_version", "source_digest", "PACKAGES", "EXCLUDED"]

#: The import packages whose code is digested.
PACKAGES = ("abco_envs", "abco_data", "abco_train")
#: Parts of them that format, schedule or present results and never change a number.
EXCLUDED = ("abco_train/report", "abco_train/bench", "abco_train/cli.py",
            "abco_train/cli_play.py", "abco_train/__main__.py", "abco_data/cli.py")  # fmt: skip


def package_version() -> str:
    """The installed ``abco`` distribution's version (one home for it: ``pyproject.toml``)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("abco")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def _without_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with every module, class and function docstring removed (in place)."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):  # fmt: skip
            node.body = body[1:] or [ast.Pass()]
    return tree


def source_digest(root: Path) -> str:
    """The 16-hex-digit digest of the code of :data:`PACKAGES` under ``root`` (files in
    sorted order, each as its path and the dump of its syntax tree without docstrings)."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            if any(rel == e or rel.startswith(e + "/") for e in EXCLUDED):
                continue
            tree = _without_docstrings(ast.parse(path.read_bytes(), filename=rel))
            digest.update(rel.encode() + b"\0" + ast.dump(tree).encode() + b"\0")
    return digest.hexdigest()[:16]


@lru_cache(maxsize=1)
def code_version() -> dict[str, str]:
    """``{"version": the abco package version, "source": source_digest(...)}`` of the code
    this process runs (computed once, about 0.3 s)."""
    return {"version": package_version(),
            "source": source_digest(Path(__file__).resolve().parents[2])}  # fmt: skip
