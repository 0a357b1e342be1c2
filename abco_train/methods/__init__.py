"""Imitation-from-observation methods behind one interface, and their registry.

A method implements :class:`Method` and registers under one or more names with
:func:`register`; the harness (:func:`abco_train.harness.loop.train`) trains and evaluates
every method the same way. Built in:

* :mod:`abco_train.methods.bco`: BC, BCO, BCO(alpha) and ABCO(alpha) with Table 2's
  ablations, switches of one implementation;
* :mod:`abco_train.methods.iupe`: IUPE;
* :mod:`abco_train.methods.ilpo`: ILPO;
* :mod:`abco_train.methods.gaifo`: GAIfO.
"""

from abco_train.methods.base import INTERACTION_KINDS, Method, TrainingFailed
from abco_train.methods.registry import (
    PluginError,
    available,
    get_method,
    load_plugins,
    register,
    resolve_config,
)

__all__ = ["Method", "TrainingFailed", "INTERACTION_KINDS", "register", "get_method",
           "available", "load_plugins", "resolve_config", "PluginError"]  # fmt: skip
