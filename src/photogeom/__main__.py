"""``python -m photogeom``: the ``photogeom`` command."""

from .cli.main import main

if __name__ == "__main__":
    main()
