from dockfactory.eval.cli import main   # allowed: the entry point
main()
