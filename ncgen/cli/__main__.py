"""``python -m ncgen.cli``: the ``ncgen`` command."""
import sys

from ncgen.cli import main

sys.exit(main())
