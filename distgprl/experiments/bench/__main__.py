"""``python -m distgprl.experiments.bench [--quick] [--out DIR]``."""

from distgprl.experiments.bench.cli import main

if __name__ == "__main__":
    main()
