"""``abco report``: the runs of a grid read back, tables, aggregates, statistics, plots and the
published numbers they are set against (:func:`abco_train.report.write.write_report`)."""
