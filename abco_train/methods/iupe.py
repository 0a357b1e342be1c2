"""IUPE: Imitating Unknown Policies via Exploration (Gavenski et al., BMVC 2020).

IUPE is ABCO(alpha) (:mod:`abco_train.methods.bco.family`) with one change in where its
post-demonstrations
come from. The paper lists three ingredients; here is where each lives:

1. *A sampling mechanism against bad local minima*: the IDM's training set ``I_s`` is
   re-sampled every iteration from the goal-reaching post-demonstrations in proportion to the
   win rate ``P(g|E)`` and their action distribution, the rest from ``I_pre`` by its own
   action distribution (ABCO's partial sampling, Eqs. 4-6 of the ABCO paper;
   :func:`abco_train.methods.bco.sampling.sample_training_set`).
2. *A sampling mechanism for exploration*: the post-demonstration rollouts draw every action
   from the policy's softmax, ``a_t ~ pi(. | s_t)``, instead of its argmax
   (:meth:`IUPE.explore`), so an uncertain policy tries the actions it is unsure about and
   the IDM sees them with their true labels. Evaluation (the figures reported) stays greedy.
3. *Self-attention* in both networks (SAGAN modules, :mod:`abco_train.networks.builders`).

The exploration rollouts run the same episodes as the evaluation (mazes: every layout of the
train split) and are counted as ``post_demonstration`` interactions (with a ``--budget``, the
harness cuts them at the interactions left); the greedy evaluation runs are not (for ABCO they
are the post-demonstrations and are counted).

It is registered through :func:`abco_train.methods.registry.register` like any plugin.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from abco_train.methods.bco.family import BCOFamily
from abco_train.methods.registry import register

__all__ = ["IUPE", "IUPE_VARIANT"]

#: ABCO's switches for IUPE: attention, partial (goal-reaching) sampling, iterative.
IUPE_VARIANT: dict[str, Any] = {"attention": True, "idm_data": "partial", "iterative": True}


@register("iupe")
class IUPE(BCOFamily):
    """ABCO(alpha) whose post-demonstrations are sampled from the policy's softmax."""

    explores = True

    @classmethod
    def variant(cls, name: str) -> dict[str, Any]:
        """IUPE's switches (:data:`IUPE_VARIANT`)."""
        return IUPE_VARIANT

    @torch.no_grad()
    def explore(self, obs: np.ndarray) -> np.ndarray:
        """``a ~ softmax(policy(s))`` for a batch, drawn from the run's generator.

        One uniform draw per observation is compared with the cumulative probabilities
        (inverse-CDF sampling), so a seed fixes every explored action.
        """
        self.policy.eval()
        logits = self.policy(torch.as_tensor(obs, device=self.device))
        probs = torch.softmax(logits.double(), dim=1).cpu().numpy()
        u = self.rng.random(len(probs))[:, None]
        return np.minimum((probs.cumsum(axis=1) < u).sum(axis=1), probs.shape[1] - 1)
