from dockfactory.core.cycle_a import *  # noqa: F401,F403
