"""Minari in and out: importing a Minari dataset as an abco dataset
(:mod:`~abco_data.interop.minari_import`) and exporting one to Minari
(:mod:`~abco_data.interop.minari_export`); both need the optional extra ``abco[minari]``."""
