"""abco_train: ABCO(alpha) and its baselines, trained on abco datasets, evaluated one way.

``abco train --env AbcoMaze5x5-v0 --method abco --seed 0`` runs
:func:`abco_train.harness.loop.train`
on :class:`abco_train.config.run.RunConfig`'s defaults. Importing this package does not import
torch;
its modules do. A trained policy: ``abco_train.load_policy(run_dir)``
(:mod:`abco_train.harness.trained_policy`).
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # provided lazily by ``__getattr__`` below (it imports torch)
    from abco_train.harness.trained_policy import Policy, load_policy


from abco_train.harness.code_version import package_version

__version__ = package_version()

__all__ = ["__version__", "load_policy", "Policy"]


def __getattr__(name: str) -> Any:
    # ``abco_train.load_policy`` without importing torch on ``import abco_train``.
    if name in ("load_policy", "Policy"):
        from abco_train.harness import trained_policy as policy

        return getattr(policy, name)
    raise AttributeError(f"module 'abco_train' has no attribute {name!r}")
