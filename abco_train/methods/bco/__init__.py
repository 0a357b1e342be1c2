"""The BCO family: BC, BCO, BCO(alpha) and ABCO(alpha) with Table 2's ablations, switches of one
implementation (:mod:`abco_train.methods.bco.family`), and ABCO's sampling of ``I_s``
(:mod:`abco_train.methods.bco.sampling`)."""
