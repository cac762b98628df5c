"""``python -m dynsens``: the same commands as the ``dynsens`` console script."""
from .cli.main import main

if __name__ == "__main__":
    main()
