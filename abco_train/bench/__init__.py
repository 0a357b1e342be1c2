"""``abco bench``: a grid of (env, method, seed) runs (:mod:`abco_train.bench.grid`), its
cells (:mod:`abco_train.bench.cells`) and the seeds and layouts they number
(:mod:`abco_train.bench.ranges`), its tracks (:mod:`abco_train.bench.tasks`), its results
file and log
(:mod:`abco_train.bench.results_log`), the records read defensively
(:mod:`abco_train.bench.records`), the one-writer lock of its folder
(:mod:`abco_train.bench.lock`), and where cells run (:mod:`abco_train.bench.backends`)."""
