"""``python -m ncgen.cli``: the ``ncgen`` command."""
import sys

from ncgen.cli import main

if __name__ == "__main__":          # not again in the processes a sweep spawns
    sys.exit(main())
