import dockfactory.cli  # noqa: F401  (a module-level edge: the fixture's cycle runs through it)


def main():
    from dockfactory.cli import main as cli_main   # allowed: the entry point defers the command line
    return cli_main()
