"""The cases of ``tools/attack.py``, one module per family of the trust issue.

Each family module has ``FAMILY`` (its name in the table) and ``cases()`` (its
:class:`~attacks.core.Case` list); :data:`FAMILY_MODULES` lists them in the table's order.
"""

from __future__ import annotations

FAMILY_MODULES = (
    "attacks.checkpoints",
    "attacks.outputs",
    "attacks.locks",
    "attacks.swapped",
    "attacks.bounds",
    "attacks.records",
    "attacks.run_folders",
    "attacks.inputs",
)
