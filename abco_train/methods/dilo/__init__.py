"""DILO (:mod:`abco_train.methods.dilo.method`) and its options."""
