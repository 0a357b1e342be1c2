"""The method registry and the plugin loader.

Built-in methods register themselves when their module is imported (:data:`BUILTIN_MODULES`,
imported on the first lookup); a plugin registers its own with :func:`register` and is
imported by :func:`load_plugins` (``--plugin``), the same for ``abco train`` and ``abco bench``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, fields
from typing import Any, TypeVar

from abco_data.user.code import import_user_module, names_a_file
from abco_train.config.fields import MethodOptions
from abco_train.config.run import MOVED_TO_METHOD_OPTIONS, ConfigError, RunConfig, comparable
from abco_train.methods.base import Method

__all__ = ["register", "get_method", "available", "load_plugins", "resolve_config",
           "PluginError", "BUILTIN_MODULES", "config_from_record", "identity",
           "builtin_options", "method_names", "options_class", "scoped_options"]  # fmt: skip

#: Modules whose import registers the built-in methods (imported on first lookup).
BUILTIN_MODULES = (
    "abco_train.methods.bco.family",
    "abco_train.methods.iupe",
    "abco_train.methods.ilpo.method",
    "abco_train.methods.gaifo.method",
    "abco_train.methods.dilo.method",
    "abco_train.methods.lapo.method",
    "abco_train.methods.reference",
)

_REGISTRY: dict[str, type[Method]] = {}

#: A method class: :func:`register` hands back the class it was given, its type kept.
_MethodClass = TypeVar("_MethodClass", bound="type[Method]")


class PluginError(ImportError):
    """A ``--plugin`` that cannot be imported; the message names it and the reason."""


def register(*names: str) -> Callable[[_MethodClass], _MethodClass]:
    """Class decorator: make a :class:`Method` available under ``names``."""

    def decorate(cls: _MethodClass) -> _MethodClass:
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


def method_names() -> tuple[str, ...]:
    """Every method name a run may give: the built-in ones (read without importing torch)
    and those registered so far (plugins loaded)."""
    return tuple(dict.fromkeys([*builtin_options(), *_REGISTRY]))


def builtin_options() -> dict[str, type[MethodOptions]]:
    """The options class of each built-in method, read without importing torch (the command
    line builds its flags from them)."""
    from abco_train.methods.bco.options import VARIANTS, BCOOptions
    from abco_train.methods.dilo.options import DILOOptions
    from abco_train.methods.gaifo.options import GAIfOOptions
    from abco_train.methods.ilpo.options import ILPOOptions
    from abco_train.methods.lapo.options import LAPOOptions

    return {**dict.fromkeys(VARIANTS, BCOOptions), "iupe": BCOOptions, "ilpo": ILPOOptions,
            "gaifo": GAIfOOptions, "dilo": DILOOptions, "lapo": LAPOOptions,
            "random": MethodOptions, "expert": MethodOptions}  # fmt: skip


def scoped_options(method: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` as they apply to ``method``: a plain name (``idm_epochs``, from a shared
    flag) to every method that has it; a name under a method's flag prefix (``lapo-schedule``,
    from ``--lapo-schedule``) to the methods whose options carry that prefix only, over a
    plain one of the same name. Field names hold no ``-``, so the prefix ends at the last.

    Example:
        >>> scoped_options("bco", {"schedule": "epochs", "lapo-schedule": "steps"})
        {'schedule': 'epochs'}
        >>> scoped_options("lapo", {"schedule": "converged", "lapo-schedule": "steps"})
        {'schedule': 'steps'}
    """
    prefix = options_class(method).flag_prefix
    plain = {k: v for k, v in options.items() if "-" not in k}
    own = {k[len(prefix):]: v for k, v in options.items()
           if prefix and k.startswith(prefix) and "-" not in k[len(prefix):]}  # fmt: skip
    return {**plain, **own}


def options_class(name: str) -> type[MethodOptions]:
    """The options class of the method registered as ``name`` (a built-in one without
    importing torch; a plugin's once its plugin is loaded).

    Raises:
        ConfigError: Unknown name.
    """
    table = builtin_options()
    if name in table:
        return table[name]
    return _REGISTRY[name].Options if name in _REGISTRY else get_method(name).Options


def resolve_config(config: RunConfig) -> RunConfig:
    """``config`` validated, with every default filled in, the method's own included, the
    settings the method fixes set (:meth:`~abco_train.methods.base.Method.fixed`: a record
    of an older version that gave them otherwise resolves to the same run), and
    ``method_options`` replaced by the method's resolved options.

    Raises:
        ConfigError: A bad setting or option, unknown env or unknown method.
    """
    config.validate()
    method = get_method(config.method)
    resolved = config.resolved(method.defaults(config.method))
    resolved = resolved.replace(**method.fixed(config.method)).validate()
    return resolved.replace(method_options=method.resolve_options(resolved).to_dict())


def config_from_record(values: Mapping[str, Any]) -> RunConfig:
    """A :class:`RunConfig` from a ``config.json`` of any version.

    Settings that were run-config fields before they became the BCO family's options
    (:data:`~abco_train.config.run.MOVED_TO_METHOD_OPTIONS`) are moved into
    ``method_options`` where the method has them (``method_options`` wins) and dropped
    where it has not (other methods never read them).

    Raises:
        ConfigError: A key that is no setting, or an unknown method.
    """
    values = dict(values)
    moved = {k: values.pop(k) for k in MOVED_TO_METHOD_OPTIONS if k in values}
    unknown = sorted(set(values) - {f.name for f in fields(RunConfig)})
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(unknown)}")
    names = options_class(str(values.get("method", RunConfig.method))).names()
    given = values.get("method_options") or {}
    if not isinstance(given, dict):
        raise ConfigError(f"method_options must be an object, got {given!r}")
    values["method_options"] = {
        **{k: v for k, v in moved.items() if k in names and v is not None}, **given
    }
    return RunConfig(**values)


def identity(values: Mapping[str, Any]) -> dict[str, Any]:
    """What makes a recorded run what it is: its config read with :func:`config_from_record`,
    resolved, without the runtime fields; the record as it is where it no longer resolves
    (an unknown method, say), so that it differs from every config that does."""
    try:
        return comparable(asdict(resolve_config(config_from_record(values))))
    except (ConfigError, TypeError):
        return comparable(values)


#: The methods that each plugin (by module name) registered when it was imported: a plugin is
#: imported once, and :func:`load_plugins` may be asked for it again.
_PLUGIN_METHODS: dict[str, tuple[str, ...]] = {}


def load_plugins(plugins: Sequence[str]) -> None:
    """Import each plugin: a ``.py`` file path or a module name (``my_pkg.my_method``).

    Importing a plugin registers its methods (:func:`register`). A file is imported once, as
    module ``abco_plugin_{stem}``.

    Raises:
        PluginError: A missing file or module, one that fails to import (the message names it
            and the reason; the original exception is chained), or one that registers no
            method.
    """
    for plugin in plugins:
        before = dict(_REGISTRY)
        module = _import_plugin(plugin)
        if module not in _PLUGIN_METHODS:
            builtin = set(builtin_options())  # imported by the plugin, perhaps: not its own
            _PLUGIN_METHODS[module] = tuple(
                name for name, cls in _REGISTRY.items()
                if before.get(name) is not cls
                and not (name in builtin and cls.__module__ in BUILTIN_MODULES)
            ) or tuple(name for name, cls in _REGISTRY.items()  # imported before, elsewhere
                       if f"{cls.__module__}.".startswith(f"{module}."))  # fmt: skip
        if not _PLUGIN_METHODS[module]:
            raise PluginError(f"plugin {plugin} registered no method (a plugin registers its "
                              "methods with abco_train.methods.register)")  # fmt: skip


def _import_plugin(plugin: str) -> str:
    """Import ``plugin`` (once); its module name."""
    try:
        return import_user_module(plugin, "abco_plugin").__name__
    except FileNotFoundError:
        raise PluginError(f"plugin file {plugin} does not exist") from None
    except Exception as exc:
        missing = not names_a_file(plugin) and isinstance(exc, ModuleNotFoundError) and \
            exc.name is not None and f"{plugin}.".startswith(f"{exc.name}.")  # not an import of it
        raise PluginError(f"plugin module {plugin!r} not found ({exc})" if missing else
                          f"plugin {plugin} failed to import: {type(exc).__name__}: {exc}"
                          ) from exc  # fmt: skip
