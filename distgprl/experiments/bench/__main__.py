"""``python -m distgprl.experiments.bench [--quick] [--out DIR] [--worker ...]``."""

from distgprl.experiments.bench.cli import main

if __name__ == "__main__":
    main()
