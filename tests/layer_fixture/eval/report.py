"""Fine: eval may import anything below."""
from dockfactory.core.geometry import norm  # noqa: F401
from dockfactory.generator import worker  # noqa: F401
from dockfactory.solver.docking import solve  # noqa: F401


def build_report():
    import matplotlib.pyplot as plt   # fine: heavy
    return plt
