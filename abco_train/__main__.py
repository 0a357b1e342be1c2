"""``python -m abco_train`` = the ``abco`` command."""

from abco_train.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
