"""GAIfO (Torabi et al. 2018): the method (:mod:`abco_train.methods.gaifo.method`) over
stable-baselines3's PPO."""
