"""``python -m dockfactory``: the command line (same as the ``dockfactory`` script)."""
import sys

from dockfactory.cli import main

sys.exit(main())
