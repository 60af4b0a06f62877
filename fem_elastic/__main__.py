"""``python -m fem_elastic``: the ``fem-elastic`` command (:mod:`fem_elastic.app.cli`)."""

import sys

from .app.cli import main

if __name__ == "__main__":  # pragma: no cover - run as a program
    sys.exit(main())
