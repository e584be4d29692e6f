"""``python -m protocols``: the navtwin command line."""
import sys

from .cli import main

sys.exit(main())
