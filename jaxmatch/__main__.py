"""``python -m jaxmatch``: the ``jaxmatch`` command."""

from jaxmatch.cli import main

if __name__ == "__main__":
    main()
