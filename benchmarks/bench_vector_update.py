"""Milliseconds per update of the vector networks, with the attention's two softmax forms.

The vector encoder's self-attention attends over a dozen feature positions. Torch's CPU
softmax over a last dimension that short is slow fore and back, so
:meth:`abco_train.networks.layers.SelfAttention2d.attend` takes the same softmax over the
leading dim of the scores laid out ``(i, B, j)`` on maps shorter than ``SHORT_SOFTMAX``
positions. This script times one update of the BCO family's vector IDM and policy
(cross-entropy on both, Adam, batch 512, one torch thread) with that path and with torch's
last-dimension softmax (the peer: the form every map took before), interleaved round by
round, and prints the medians and their ratio.

Usage::

    python benchmarks/bench_vector_update.py
    python benchmarks/bench_vector_update.py --obs-dims 4,6,8 --rounds 7 --updates 100
    python benchmarks/bench_vector_update.py --tiny      # seconds: a smoke test, no figures
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from gymnasium import spaces

from abco_train.networks import layers
from abco_train.networks.builders import build_networks

BATCH = 512


def update_ms(obs_dim: int, actions: int, updates: int, short_softmax: int) -> float:
    """Mean milliseconds of one IDM + policy update on random data (seeded)."""
    layers.SHORT_SOFTMAX = short_softmax  # read at call time by SelfAttention2d.attend
    torch.manual_seed(0)
    box = spaces.Box(-1.0, 1.0, (obs_dim,))
    policy, idm = build_networks(box, actions, arch="mlp", attention=True)
    opt = torch.optim.Adam([*policy.parameters(), *idm.parameters()], 1e-3)
    s, s1 = torch.randn(BATCH, obs_dim), torch.randn(BATCH, obs_dim)
    a = torch.randint(0, actions, (BATCH,))

    def step() -> None:
        loss = (torch.nn.functional.cross_entropy(idm(s, s1), a)
                + torch.nn.functional.cross_entropy(policy(s), a))  # fmt: skip
        opt.zero_grad()
        loss.backward()
        opt.step()

    for _ in range(10):  # warm-up: allocator, first-call dispatch
        step()
    start = time.perf_counter()
    for _ in range(updates):
        step()
    return (time.perf_counter() - start) / updates * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--obs-dims", default="4,6,8", help="observation sizes (CartPole 4, "
                        "Acrobot 6, LunarLander 8)")  # fmt: skip
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (medians)")
    parser.add_argument("--updates", type=int, default=100, help="updates timed per round")
    parser.add_argument("--tiny", action="store_true", help="one round of 2 updates, size 4")
    args = parser.parse_args()
    if args.tiny:
        args.obs_dims, args.rounds, args.updates = "4", 1, 2
    torch.set_num_threads(1)
    shipped = layers.SHORT_SOFTMAX
    print(f"torch {torch.__version__}, 1 thread, batch {BATCH}, medians of {args.rounds} rounds")
    print(f"{'obs':>4} {'transposed ms':>14} {'last-dim ms':>12} {'ratio':>6}")
    for dim in (int(d) for d in args.obs_dims.split(",")):
        ours, peer = [], []
        for _ in range(args.rounds):
            ours.append(update_ms(dim, 4, args.updates, shipped))
            peer.append(update_ms(dim, 4, args.updates, 0))
        a, b = statistics.median(ours), statistics.median(peer)
        print(f"{dim:>4} {a:>14.2f} {b:>12.2f} {a / b:>6.2f}", flush=True)
    layers.SHORT_SOFTMAX = shipped


if __name__ == "__main__":
    main()
