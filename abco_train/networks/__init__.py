"""The networks of the methods: shared layers, encoders, heads, the maze-cell networks, and one
table from architecture name to builder (:func:`abco_train.networks.builders.build_networks`)."""
