"""Making the built-in datasets: deterministic generation from ``abco_envs``' experts and
random policies (:mod:`~abco_data.generation.generate`), the bounds every creation parameter is
checked against first (:mod:`~abco_data.generation.bounds`), and the reference returns an
expert and a random policy score (:mod:`~abco_data.generation.reference`)."""
