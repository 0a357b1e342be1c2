"""abco_train: ABCO(alpha) and its baselines, trained on abco datasets, evaluated one way.

``abco train --env AbcoMaze5x5-v0 --method abco --seed 0`` runs :func:`abco_train.train.train`
on :class:`abco_train.config.RunConfig`'s defaults. Importing this package does not import torch;
its modules do.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
