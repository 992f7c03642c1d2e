from dockfactory.cli import main   # allowed: the entry point
main()
