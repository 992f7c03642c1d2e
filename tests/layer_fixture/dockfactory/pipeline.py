"""The app layer may import every layer below it (fine)."""
from dockfactory.eval import report  # noqa: F401
from dockfactory.generator import sampler  # noqa: F401
