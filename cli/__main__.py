"""``python -m cli``: the navtwin command line."""
import sys

from .main import main

sys.exit(main())
