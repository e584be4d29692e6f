"""``python -m navtwin``: the navtwin command line."""
import sys

from .cli.main import main

sys.exit(main())
