"""``abco bench``: a grid of (env, method, seed) runs, its results log, where cells run."""
