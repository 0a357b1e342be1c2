"""Typed settings: one machinery for the run config and every method's options.

A setting is a dataclass field made by :func:`option`, carrying its help text and its checks
(``choices``, a lower bound ``min`` (``exclusive`` or not), an upper bound ``max``) and, where
a tuner may change it, its range (``search``: a :class:`Search`). From the
fields come the command-line options (:func:`add_field_options`: help, choices, defaults), the
checks of a value from the command line or a JSON file (:func:`check_fields`: type, finite
numbers, choices, bounds; one :class:`ConfigError` naming the option) and, for a method, its
typed options (:class:`MethodOptions`: unknown keys refused, defaults filled from tables).

Importing this module imports neither torch nor gymnasium.

Example:
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Opts(MethodOptions):
    ...     steps: int | None = option("training steps", min=1)
    >>> Opts.resolve({"steps": 5}, defaults={"steps": 100}, method="demo")
    Opts(steps=5)
    >>> Opts.resolve({"stpes": 5}, defaults={}, method="demo")
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: unknown demo option(s) stpes; known: steps
"""

from __future__ import annotations

import argparse
import json
import math
import types
import typing
from collections.abc import Callable, Collection, Mapping
from dataclasses import MISSING, Field, asdict, dataclass, field, fields
from functools import partial
from typing import Any, ClassVar

from typing_extensions import Self

__all__ = ["ConfigError", "option", "flag_of", "check_fields", "add_field_options",
           "MethodOptions", "Search", "search_space", "json_object", "int_list",
           "count"]  # fmt: skip


class ConfigError(ValueError):
    """A setting out of its range or choices; the message names the option and the value."""


def option(help: str, default: Any = None, **checks: Any) -> Any:
    """A setting: a dataclass field with its help text and checks (``choices``, ``min``,
    ``exclusive``, ``max``) as metadata."""
    return field(default=default, metadata={"help": help, **checks})


@dataclass(frozen=True)
class Search:
    """The range a tuner (``abco tune``) searches for a setting: numbers from ``low`` to
    ``high`` (``log``: on a log scale; whole numbers for an ``int`` setting), or one of
    ``choices``. ``read_when``: ``(option, value)`` pairs that must all hold of a run's
    resolved options for it to read the setting at all (an epoch count under a converged
    schedule is never read: a tuner that drew it would search nothing).

    Example:
        >>> Search(1e-4, 1e-2, log=True).describe(float), Search(choices=(32, 64)).describe(int)
        ('float in [0.0001, 0.01], log scale', 'one of 32, 64')
        >>> epochs = Search(1, 16, read_when=(("schedule", "epochs"),))
        >>> epochs.describe(int), epochs.reads({"schedule": "converged"})
        ('int in [1, 16] (read where schedule is epochs)', False)
    """

    low: float = 0.0
    high: float = 0.0
    log: bool = False
    choices: tuple[Any, ...] = ()
    read_when: tuple[tuple[str, Any], ...] = ()

    def reads(self, options: Any) -> bool:
        """Whether a run with the resolved ``options`` (a mapping or an options object; an
        option it lacks counts as unset) reads the setting."""
        get = options.get if isinstance(options, Mapping) else partial(getattr, options)
        return all(get(name, None) == value for name, value in self.read_when)

    def suggest(self, trial: Any, name: str, kind: type) -> Any:
        """The value an Optuna ``trial`` suggests for the setting ``name`` of type ``kind``."""
        if self.choices:
            return trial.suggest_categorical(name, list(self.choices))
        if kind is int:
            return trial.suggest_int(name, int(self.low), int(self.high), log=self.log)
        return trial.suggest_float(name, float(self.low), float(self.high), log=self.log)

    def contains(self, value: Any, kind: type) -> bool:
        """Whether ``value`` is one a tuner could have chosen for a setting of type ``kind``."""
        if self.choices:
            return value in self.choices
        if isinstance(value, bool) or not isinstance(value, int if kind is int else (int, float)):
            return False
        return self.low <= value <= self.high

    def describe(self, kind: type) -> str:
        """The range in words."""
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices)) + self._condition()
        low, high = (int(self.low), int(self.high)) if kind is int else (self.low, self.high)
        text = f"{kind.__name__} in [{low}, {high}]" + (", log scale" if self.log else "")
        return text + self._condition()

    def _condition(self) -> str:
        if not self.read_when:
            return ""
        return " (read where " + " and ".join(
            f"{name} is {'unset' if value is None else value}"
            for name, value in self.read_when) + ")"  # fmt: skip


def search_space(cls: type) -> dict[str, tuple[Search, type]]:
    """The settings of the dataclass ``cls`` a tuner may change: name -> (range, type)."""
    hints = typing.get_type_hints(cls)
    return {f.name: (f.metadata["search"], base_type(hints[f.name]))
            for f in fields(cls) if "search" in f.metadata}  # fmt: skip


def flag_of(name: str, prefix: str = "") -> str:
    """The command-line option of a field: ``idm_epochs`` -> ``--idm-epochs``."""
    return "--" + prefix + name.replace("_", "-")


def base_type(hint: Any) -> Any:
    """``int`` of ``int | None``; the type itself otherwise."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return args[0]
    return typing.get_origin(hint) or hint


def _optional(hint: Any) -> bool:
    return type(None) in typing.get_args(hint)


def _type_problem(value: Any, kind: Any) -> str | None:
    """Why ``value`` is not of ``kind`` (``None`` when it is)."""
    if kind is bool:
        return None if isinstance(value, bool) else "must be true or false"
    if kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        return None if ok else "must be an integer"
    if kind is float:
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return "must be a number"
        return None if math.isfinite(value) else "must be a finite number"
    if kind is str:
        return None if isinstance(value, str) else "must be a string"
    if kind is dict:
        return None if isinstance(value, dict) else "must be a JSON object"
    if kind is list:
        return None if isinstance(value, list) else "must be a list"
    return None


def check_value(f: Field[Any], hint: Any, value: Any, flag: str) -> None:
    """Check one field's value: type, finite numbers, choices, bounds.

    Raises:
        ConfigError: The value does not fit (the message names ``flag`` and the value).
    """
    if value is None:
        if _optional(hint) or f.default is None:
            return
        raise ConfigError(f"{flag} must be set, got null")
    problem = _type_problem(value, base_type(hint))
    if problem:
        raise ConfigError(f"{flag} {problem}, got {value!r}")
    choices, low, high = f.metadata.get("choices"), f.metadata.get("min"), f.metadata.get("max")
    if choices is not None and value not in choices:
        raise ConfigError(f"{flag} must be one of {', '.join(map(str, choices))}, got {value!r}")
    if low is not None:
        exclusive = f.metadata.get("exclusive", False)
        if value < low or (exclusive and value == low):
            raise ConfigError(f"{flag} must be {'>' if exclusive else '>='} {low}, got {value}")
    if high is not None and value > high:
        raise ConfigError(f"{flag} must be <= {high:,}, got {value}")


def check_fields(obj: Any, prefix: str = "") -> None:
    """Check every field of the dataclass instance ``obj`` (see :func:`check_value`).

    Raises:
        ConfigError: The first field that does not fit, named as its command-line option.
    """
    hints = typing.get_type_hints(type(obj))
    for f in fields(obj):
        check_value(f, hints[f.name], getattr(obj, f.name), flag_of(f.name, prefix))


def json_object(text: str) -> dict[str, Any]:
    """An argparse type: a JSON object (``'{"k": 1}'``)."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    except RecursionError:
        raise argparse.ArgumentTypeError("not JSON abco reads: nested too deeply") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"k\": 1}'")
    return value


def int_list(text: str) -> list[int]:
    """An argparse type: comma-separated integers (``64,64``)."""
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of integers: {text!r}"
                                         ) from None  # fmt: skip


def count(most: int) -> Callable[[str], int]:
    """An argparse type: an integer from 1 to ``most`` (``count(50)("8") == 8``)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if not 1 <= value <= most:
            raise argparse.ArgumentTypeError(f"must be from 1 to {most:,}, got {value}")
        return value

    return parse


def add_field_options(
    parser: argparse.ArgumentParser | Any,
    cls: type,
    *,
    exclude: Collection[str] = (),
    unset_defaults: bool = False,
    prefix: str = "",
    dest_prefix: str = "",
    shown_default: str = "per env, preset and method",
) -> None:
    """Add one option per field of the dataclass ``cls`` to ``parser`` (or an argument group).

    Args:
        parser: The parser or argument group.
        cls: The dataclass whose fields become options.
        exclude: Fields left out.
        unset_defaults: Every option defaults to ``None`` ("not set"), as for ``abco bench``'s
            overrides; otherwise an option defaults to its field's default.
        prefix: Put before each flag (``ilpo-`` -> ``--ilpo-latents``).
        dest_prefix: Put before each destination in the parsed namespace.
        shown_default: The help's words for a ``None`` default.
    """
    hints = typing.get_type_hints(cls)
    for f in fields(cls):
        if f.name in exclude:
            continue
        kind = base_type(hints[f.name])
        default = None if f.default is MISSING else f.default
        help_text = f.metadata.get("help", "")
        if "(default" not in help_text:  # a help text may name its default itself
            empty = f.default_factory is not MISSING  # an empty dict or list by default
            shown = "none" if empty else shown_default if default is None else default
            help_text += f" (default: {shown})"
        kwargs: dict[str, Any] = {"default": None if unset_defaults else default,
                                  "dest": dest_prefix + f.name,
                                  "help": help_text.replace("%", "%%")}  # fmt: skip
        flag = flag_of(f.name, prefix)
        if kind is bool:
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, **kwargs)
        elif kind is dict:
            kwargs["default"] = None if unset_defaults else {}
            parser.add_argument(flag, type=json_object, metavar="JSON", **kwargs)
        elif kind is list:
            parser.add_argument(flag, type=int_list, metavar="N[,N...]", **kwargs)
        else:
            choices = f.metadata.get("choices")
            metavar = None if choices else f.name.upper()
            parser.add_argument(flag, type=kind, choices=choices, metavar=metavar, **kwargs)


@dataclass
class MethodOptions:
    """A method's own settings, typed; a subclass declares its fields with :func:`option`.

    ``None`` fields are filled from the method's default tables (:meth:`resolve`); the
    resolved options are stored in the run's ``config.json`` under ``method_options``.
    """

    #: Put before each option's flag on the command line (``ilpo-``: ``--ilpo-latents``).
    flag_prefix: ClassVar[str] = ""
    #: The run config's tunable settings (``search``) the method reads: a tuner searches them
    #: beside the method's own (a method whose networks ignore ``--lr`` lists none).
    run_search: ClassVar[tuple[str, ...]] = ("lr",)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The option names."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def searched(cls, method: str) -> tuple[str, ...]:
        """The options with a ``search`` range that ``method`` reads (a class shared by
        several methods leaves out what one of them ignores)."""
        return tuple(search_space(cls))

    @classmethod
    def resolve(cls, given: Mapping[str, Any], defaults: Mapping[str, Any], method: str
                ) -> Self:  # fmt: skip
        """The options: ``given`` (the user's) over ``defaults``, checked.

        Raises:
            ConfigError: An unknown option (for any method) or a value that does not fit.
        """
        known = cls.names()
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise ConfigError(f"unknown {method} option(s) {', '.join(unknown)}; known: "
                              f"{', '.join(sorted(known)) or 'none'}")  # fmt: skip
        values = {**{k: v for k, v in defaults.items() if k in known}, **given}
        options = cls(**values)
        check_fields(options, cls.flag_prefix)
        return options

    @classmethod
    def for_run(cls, config: Any, method: str) -> Self:
        """The options of a run (``config``: its :class:`~abco_train.config.run.RunConfig`):
        its ``method_options`` over the fields' defaults. Options whose defaults depend on the
        environment override this with their tables.

        Raises:
            ConfigError: An unknown option or a value that does not fit.
        """
        return cls.resolve(config.method_options, {}, method)

    def to_dict(self) -> dict[str, Any]:
        """The options as a JSON-ready dict."""
        return asdict(self)
