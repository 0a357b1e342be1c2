"""``python -m abco_data``: the dataset command line (see :mod:`abco_data.cli`)."""

import sys

from abco_data.cli import main

if __name__ == "__main__":
    sys.exit(main())
