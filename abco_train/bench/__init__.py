"""``abco bench``: a grid of (env, method, seed) runs (:mod:`abco_train.bench.grid`), its
cells (:mod:`abco_train.bench.cells`), its results file and log
(:mod:`abco_train.bench.results_log`), and where cells run (:mod:`abco_train.bench.backends`)."""
