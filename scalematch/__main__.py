"""``python -m scalematch``: the command line, as the ``scalematch`` command."""

from .cli import main

if __name__ == "__main__":
    main()
