"""`python -m distgprl`: the same CLI as the `distgprl` console script."""

from distgprl.cli import main

if __name__ == "__main__":
    main()  # exits (typer's standalone mode): with 0, or the command's code
