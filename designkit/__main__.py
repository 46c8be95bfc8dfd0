"""``python -m designkit ...``: the same command line as the ``designkit`` script
(:func:`designkit.cli.main`), for environments where the script is not on PATH."""

import sys

from .cli import main

sys.exit(main())
