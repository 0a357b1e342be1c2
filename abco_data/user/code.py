"""Importing a user's code by name: a ``.py`` file path or a dotted module name, the one way
``abco train --plugin`` and ``abco data record --policy MODULE:CALLABLE`` both take it.

Example:
    >>> import_user_module("json", "abco_plugin").__name__
    'json'
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

__all__ = ["import_user_module", "names_a_file"]


def names_a_file(target: str) -> bool:
    """Whether ``target`` is read as a file path (it ends in ``.py`` or is an existing file)."""
    return target.endswith(".py") or Path(target).is_file()


def import_user_module(target: str, prefix: str) -> ModuleType:
    """Import ``target``: a ``.py`` file (once, as module ``{prefix}_{stem}``) or a module name.

    Raises:
        FileNotFoundError: ``target`` names a file that does not exist.
        ImportError: The file cannot be loaded as a module.
        Exception: Whatever the module raised while importing it (a file's half-imported
            module is not left in ``sys.modules``, so a fixed file imports on the next try).
    """
    if not names_a_file(target):
        return importlib.import_module(target)
    path = Path(target).resolve()
    if not path.is_file():
        raise FileNotFoundError(target)
    name = f"{prefix}_{path.stem}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {target}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module
