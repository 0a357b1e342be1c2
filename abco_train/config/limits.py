"""Upper bounds of every count and size the ``abco`` command takes, with their reasons.

Each is checked before any work (the run config's with its other checks, through the
fields' ``max``; the command line's by argparse or ``abco play``), far above real use, and
bounds what the value allocates or costs. docs/training.md ("Limits") lists them.

Importing this module imports nothing else of abco.
"""

from __future__ import annotations

__all__ = ["MAX_SEED", "MAX_THREADS", "MAX_ITERATIONS", "MAX_BATCH_SIZE", "MAX_PRE_TRANSITIONS",
           "MAX_EXPERT_EPISODES", "MAX_EVAL_EPISODES", "MAX_EVAL_MAX_STEPS", "MAX_PLOT_LAYOUTS",
           "MAX_JOBS", "MAX_PLAY_EPISODES", "MAX_PLAY_STEPS", "MAX_PLAY_FPS",
           "MAX_PLAY_FRAMES", "MAX_EPOCHS", "MAX_STEPS", "MAX_WIDTH", "MAX_ENVS",
           "MAX_LATENTS", "MAX_BUDGET"]  # fmt: skip

# -- the run config (abco train, abco bench) ---------------------------------------------------

#: numpy's and torch's seeds are 32- and 64-bit; derived seeds (evaluation: 200,000,000 +
#: 1000 * seed + episode) stay far inside both.
MAX_SEED = 2**31 - 1
#: Torch threads, each with a stack of its own; more threads than cores never train faster.
MAX_THREADS = 256
#: Every iteration adds its rollouts to the IDM's data, so memory grows with alpha (Acrobot's
#: default of 30 is the largest; each iteration costs seconds to minutes).
MAX_ITERATIONS = 1_000
#: A minibatch of 65,536 64x64 RGB frames is 3 GiB as float32, before any activation.
MAX_BATCH_SIZE = 65_536
#: Cuts of the datasets (they never allocate past the data itself), 500 and 100 times the
#: largest abco dataset's 190,000 transitions and 10,000 expert episodes.
MAX_PRE_TRANSITIONS = 100_000_000
MAX_EXPERT_EPISODES = 1_000_000
#: Classic control: one environment per evaluation episode, all stepped at once.
MAX_EVAL_EPISODES = 10_000
#: Ten times the longest episode of any abco environment (the mazes' 1,000 steps).
MAX_EVAL_MAX_STEPS = 10_000
#: One maze drawn per layout in a figure; past 100 the figure is unreadable and slow to draw.
MAX_PLOT_LAYOUTS = 100

# -- the command line ----------------------------------------------------------------------------

#: ``abco bench --jobs``: cells at once, a process each (a grid never runs more than its cells).
MAX_JOBS = 256
#: ``abco play``: episodes in one GIF, steps of each (the mazes' own limit, above classic
#: control's 500), frames per second (GIF delays are hundredths of a second; viewers slow
#: faster ones down) and frames in all, ``episodes * (max_steps + 1 + fps // 2)`` at most:
#: every frame (192 KiB for a maze, 703 KiB for classic control's 600x400) is held in memory
#: until the GIF is written.
MAX_PLAY_EPISODES = 1_000
MAX_PLAY_STEPS = 1_000
MAX_PLAY_FPS = 50
MAX_PLAY_FRAMES = 5_000

# -- the methods' options --------------------------------------------------------------------------

#: Epochs, patience and factors of epochs: each epoch is a pass over up to 10^8 examples.
MAX_EPOCHS = 10_000
#: Optimiser, environment and update steps (training, remapping, RL, minibatch updates): at
#: the CPU's ~1,000 steps a second, 10^8 is more than a day of one run.
MAX_STEPS = 100_000_000
#: Widths of layers (hidden units, channels, features): a 65,536 x 65,536 float32 weight is
#: 16 GiB.
MAX_WIDTH = 65_536
#: Parallel environments of a method's own (remapping, PPO rollouts), a process's worth.
MAX_ENVS = 4_096
#: Latent actions of ILPO: its forward model predicts every latent's outcome at once.
MAX_LATENTS = 1_024
#: Most environment interactions one run may be given (``--budget``).
MAX_BUDGET = 10_000_000_000
