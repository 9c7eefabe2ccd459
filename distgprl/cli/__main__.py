"""`python -m distgprl.cli`: the same CLI as the `distgprl` console script."""

import sys

from distgprl.cli import main

if __name__ == "__main__":
    sys.exit(main())
