"""``abco tune``: the same number of tuning trials for every method of a benchmark track.

Each method declares what a tuner may change: its options' ranges (``search`` on its typed
options, :class:`~abco_train.config.fields.Search`) and the run settings it reads
(``run_search``, e.g. the learning rate). ``abco tune --track headline --family classic``
runs one Optuna study per method on the track's tasks of that family (``classic``, ``maze``,
``image``), always on the track's validation seeds, whose maze runs are evaluated on
validation layouts (never the test split or the test's fresh layouts). Trial 0 is the
method's defaults; the others are drawn by Optuna's TPE sampler (seeded). A trial's value is
the mean headline score of its runs; a run that failed counts 0.

The studies live in ``OUT/optuna.journal`` (Optuna's journal storage: an interrupted tuning
resumes where it stopped, its unfinished trial re-run with the same settings); each trial's
runs in ``OUT/{family}/{method}/trial{k}``. After every trial the record is rewritten:
``trials.jsonl`` (every trial: its settings, runs and value), ``choices.json`` (the best
trial per method and family) and ``tuning.md``. ``abco report RUNS --tuned-by OUT`` shows the
tuning effort per method beside a grid's results.

Modules: :mod:`~abco_train.tune.space` (the search spaces), :mod:`~abco_train.tune.study`
(the studies), :mod:`~abco_train.tune.record` (the record, written and read back),
:mod:`~abco_train.tune.command` (the command line).
"""
