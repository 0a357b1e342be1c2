"""The method registry and the plugin loader.

Built-in methods register themselves when their module is imported (:data:`BUILTIN_MODULES`,
imported on the first lookup); a plugin registers its own with :func:`register` and is
imported by :func:`load_plugins` (``--plugin``), the same for ``abco train`` and ``abco bench``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from abco_train.config.run import ConfigError, RunConfig
from abco_train.methods.base import Method

__all__ = ["register", "get_method", "available", "load_plugins", "resolve_config",
           "PluginError", "BUILTIN_MODULES"]  # fmt: skip

#: Modules whose import registers the built-in methods (imported on first lookup).
BUILTIN_MODULES = (
    "abco_train.methods.bco.family",
    "abco_train.methods.iupe",
    "abco_train.methods.ilpo.method",
    "abco_train.methods.gaifo.method",
)

_REGISTRY: dict[str, type[Method]] = {}


class PluginError(ImportError):
    """A ``--plugin`` that cannot be imported; the message names it and the reason."""


def register(*names: str) -> Callable[[type[Method]], type[Method]]:
    """Class decorator: make a :class:`Method` available under ``names``."""

    def decorate(cls: type[Method]) -> type[Method]:
        for name in names:
            _REGISTRY[name] = cls
        return cls

    return decorate


def _builtins() -> None:
    for module in BUILTIN_MODULES:
        importlib.import_module(module)


def get_method(name: str) -> type[Method]:
    """The class registered as ``name``.

    Raises:
        ConfigError: Unknown name (the message lists the registered ones).
    """
    _builtins()
    if name not in _REGISTRY:
        raise ConfigError(f"unknown method {name!r}; registered: {', '.join(available())}"
                          " (a --plugin may register more)")  # fmt: skip
    return _REGISTRY[name]


def available() -> tuple[str, ...]:
    """Registered method names."""
    _builtins()
    return tuple(_REGISTRY)


def resolve_config(config: RunConfig) -> RunConfig:
    """``config`` validated, with every default filled in, the method's own included.

    Raises:
        ConfigError: A bad setting, unknown env or unknown method.
    """
    config.validate()
    return config.resolved(get_method(config.method).defaults(config.method)).validate()


def load_plugins(plugins: Sequence[str]) -> None:
    """Import each plugin: a ``.py`` file path or a module name (``my_pkg.my_method``).

    Importing a plugin registers its methods (:func:`register`). A file is imported once, as
    module ``abco_plugin_{stem}``.

    Raises:
        PluginError: A missing file or module, or one that fails to import (the message
            names it and the reason; the original exception is chained).
    """
    for plugin in plugins:
        if plugin.endswith(".py") or Path(plugin).is_file():
            path = Path(plugin).resolve()
            if not path.is_file():
                raise PluginError(f"plugin file {plugin} does not exist")
            name = f"abco_plugin_{path.stem}"
            if name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(name, path)
            if spec is None or spec.loader is None:
                raise PluginError(f"cannot import plugin file {plugin}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except Exception as exc:
                del sys.modules[name]
                raise PluginError(f"plugin {plugin} failed to import: "
                                  f"{type(exc).__name__}: {exc}") from exc  # fmt: skip
        else:
            try:
                importlib.import_module(plugin)
            except ModuleNotFoundError as exc:
                raise PluginError(f"plugin module {plugin!r} not found ({exc})") from exc
