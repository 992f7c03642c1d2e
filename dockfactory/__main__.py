"""``python -m dockfactory``: the command line (same as the ``dockfactory`` script)."""
import sys

from dockfactory.entry import main

sys.exit(main())
