from dockfactory.solver import docking  # noqa: F401


def identify(x):
    return x
