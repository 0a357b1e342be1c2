"""ILPO (Edwards et al., ICML 2019): the method (:mod:`abco_train.methods.ilpo.method`, which maps
the code to the paper), its options (:mod:`abco_train.methods.ilpo.options`, torch-free), its
action remapping (:mod:`abco_train.methods.ilpo.remapping`) and its networks and losses
(:mod:`abco_train.methods.ilpo.networks`)."""
