from dockfactory.entry import main   # allowed: the entry point
main()
