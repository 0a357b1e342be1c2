"""The run harness: training data, the loop, seeding and device, the run folder (its lock,
its checkpoints of data), rollouts and metrics, the trained-policy loader and the plots. Every
method is trained and evaluated here the same way (:func:`abco_train.harness.loop.train`)."""
