"""The ``dockfactory`` script's entry point: the app's environment is set before anything loads
numpy or torch (:func:`dockfactory.set_app_environment`), then the command line runs."""
import os

from dockfactory import set_app_environment


def main() -> int:
    """Set the app's environment in this process, then run :func:`dockfactory.cli.main` (exit code)."""
    set_app_environment(os.environ)
    from dockfactory.cli import main as cli_main   # numpy loads here, after the pins
    return cli_main()
