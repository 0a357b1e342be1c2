"""ILPO (Edwards et al., ICML 2019): the method (:mod:`abco_train.methods.ilpo.method`) and its
networks and losses (:mod:`abco_train.methods.ilpo.networks`)."""
