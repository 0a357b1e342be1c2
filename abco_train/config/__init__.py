"""The run config: every setting of a training run, its defaults, its checks, its options.

:class:`RunConfig` (:mod:`abco_train.config.run`) holds the harness's settings; a method's
own settings are its typed options (:mod:`abco_train.config.fields`). Importing this package
imports neither torch nor gymnasium.
"""

from abco_train.config.run import (
    ConfigError,
    RunConfig,
    add_config_options,
    config_from_args,
    env_kind,
    known_envs,
)

__all__ = ["RunConfig", "ConfigError", "add_config_options", "config_from_args", "env_kind",
           "known_envs"]  # fmt: skip
