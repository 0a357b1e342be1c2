"""Milliseconds of DILO's utility update on maze frames, its pair inputs built once or per pass.

DILO's value step reads the pairs ``(s, s')`` and ``(s', s'')`` through its online utility
(two passes) and both through its target utility (one pass over the two batches). Each pass
used to build its own input from the uint8 frames: scale both frames to floats, take the
difference, concatenate (the peer here, written out as it was). The method now builds each
batch's input once (:meth:`abco_train.networks.heads.IDMNet.pair_input`, into one buffer)
and the target reads the two inputs concatenated. Both give the same numbers to the bit (the
script checks); this times one update of the online network (Adam, its three passes, the
target's pass without gradient) with each, interleaved round by round, one torch thread,
64x64 frames (every built-in maze), and prints the medians and their ratio.

Usage::

    python benchmarks/bench_pair_inputs.py
    python benchmarks/bench_pair_inputs.py --batches 64,256 --rounds 7 --updates 20
    python benchmarks/bench_pair_inputs.py --tiny      # seconds: a smoke test, no figures
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time

import numpy as np
import torch
from gymnasium import spaces

from abco_train.networks.builders import build_networks
from abco_train.networks.heads import IDMNet

FRAME = (64, 64, 3)


def per_pass_input(obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
    """The peer: each pass scales its frames and concatenates ``(s, s' - s)`` itself."""
    obs, next_obs = obs.float().div_(255.0), next_obs.float().div_(255.0)
    return torch.cat([obs, next_obs - obs], dim=-1)


def update_ms(batch: int, updates: int, once: bool) -> tuple[float, torch.Tensor]:
    """Mean milliseconds of one update, and the online network's outputs after them."""
    torch.manual_seed(0)
    _, value = build_networks(spaces.Box(0, 255, FRAME, dtype=np.uint8), 2, attention=False)
    assert isinstance(value, IDMNet)
    target = copy.deepcopy(value).requires_grad_(False).eval()
    opt = torch.optim.Adam(value.parameters(), 1e-3)
    s, s1, s2 = (torch.randint(0, 256, (batch, *FRAME), dtype=torch.uint8) for _ in range(3))

    def step() -> None:
        if once:
            pairs = (value.pair_input(s, s1), value.pair_input(s1, s2))
            both = value.stacked_input(*pairs)
        else:
            pairs = (per_pass_input(s, s1), per_pass_input(s1, s2))
            both = per_pass_input(torch.cat([s, s1]), torch.cat([s1, s2]))
        now, after = value.from_input(pairs[0]), value.from_input(pairs[1])
        with torch.no_grad():
            goal = target.from_input(both).min(1, keepdim=True).values
        loss = ((goal[batch:] - now) ** 2).mean() + ((after - goal[:batch]) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    step()  # warm-up: allocator, first-call dispatch
    start = time.perf_counter()
    for _ in range(updates):
        step()
    elapsed = (time.perf_counter() - start) / updates * 1e3
    with torch.no_grad():
        return elapsed, value(s, s1)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--batches", default="64,256", help="rows of each of the two batches")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (medians)")
    parser.add_argument("--updates", type=int, default=20, help="updates timed per round")
    parser.add_argument("--tiny", action="store_true", help="one round of 2 updates, batch 8")
    args = parser.parse_args()
    if args.tiny:
        args.batches, args.rounds, args.updates = "8", 1, 2
    torch.set_num_threads(1)
    print(f"torch {torch.__version__}, 1 thread, {FRAME} frames, medians of {args.rounds} rounds")
    print(f"{'batch':>6} {'built once ms':>14} {'per pass ms':>12} {'ratio':>6}")
    for batch in (int(b) for b in args.batches.split(",")):
        ours, peer = [], []
        for _ in range(args.rounds):
            a, out_a = update_ms(batch, args.updates, once=True)
            b, out_b = update_ms(batch, args.updates, once=False)
            assert torch.equal(out_a, out_b), "the two forms must train the same network"
            ours.append(a)
            peer.append(b)
        a, b = statistics.median(ours), statistics.median(peer)
        print(f"{batch:>6} {a:>14.2f} {b:>12.2f} {a / b:>6.2f}", flush=True)


if __name__ == "__main__":
    main()
