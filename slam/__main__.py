"""``python -m slam`` is the ``lineslam`` command."""

from slam.cli import main

if __name__ == "__main__":
    main()
