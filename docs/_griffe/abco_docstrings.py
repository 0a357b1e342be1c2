"""Griffe extension for the API reference (``mkdocs.yml``): abco's docstrings as written.

abco's docstrings are Google style with two habits of Sphinx's reST. This extension, which
mkdocstrings runs when it loads the packages, reads them for the docs site only (the source
is left alone):

* ``Example:`` (singular) heads a doctest block; Google style names that section
  ``Examples:``, and only then are the ``>>>`` lines shown as code.
* Roles such as ``:func:`load``` and ``:class:`~abco_data.dataset.Dataset``` become optional
  cross-references: a link where the target is in the reference, plain code where it is not
  (the ``~`` shows the last name only, as in Sphinx).
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

_EXAMPLE = re.compile(r"^(\s*)Example:[ \t]*$", re.M)
_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const):`(~?)([^`]+)`")


def _target(obj: griffe.Object, name: str) -> str:
    """``name`` as a full path, resolved in ``obj``'s scope where it is relative."""
    head, _, tail = name.partition(".")
    try:
        path = obj.resolve(head)
    except Exception:  # not in scope (a full path already, or an unknown name): keep it
        return name
    return f"{path}.{tail}" if tail else path


def _role(obj: griffe.Object, match: re.Match[str]) -> str:
    short, name = match[1], match[2].strip().removesuffix("()")
    title = name.rsplit(".", 1)[-1] if short else name
    target = html.escape(_target(obj, name), quote=True)
    return f'<autoref identifier="{target}" optional><code>{html.escape(title)}</code></autoref>'


class AbcoDocstrings(griffe.Extension):
    """Rewrite ``Example:`` sections and Sphinx roles in every docstring of a loaded package."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        """Walk the package once it is loaded, when every name in it can be resolved."""
        self._walk(pkg)

    def on_package_loaded(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        """The same hook under its griffe 1 name (both rewrites are idempotent)."""
        self._walk(pkg)

    def _walk(self, obj: griffe.Object) -> None:
        if obj.docstring is not None:
            text = _EXAMPLE.sub(r"\1Examples:", obj.docstring.value)
            obj.docstring.value = _ROLE.sub(lambda m: _role(obj, m), text)
        for member in obj.members.values():
            if not member.is_alias:
                self._walk(member)
