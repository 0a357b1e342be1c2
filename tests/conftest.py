"""Shared test set-up: headless SDL for the pygame paths, and a non-interactive plot backend."""

import os

# Set before anything imports pygame or matplotlib: tests never need a display or a sound card.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
os.environ.setdefault("MPLBACKEND", "Agg")
