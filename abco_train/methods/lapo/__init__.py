"""LAPO (:mod:`abco_train.methods.lapo.method`), its networks and its options."""
