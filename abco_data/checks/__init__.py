"""What a dataset file is checked against before it is trusted: its header, read and matched
to the registry, the manifests and the generator (:mod:`~abco_data.checks.header`), and its
size and sha256 against what the manifest pins (:mod:`~abco_data.checks.checksum`).
:func:`abco_data.verify` checks every byte and value of a file with both."""
