"""VIOLATION (upward, relative): core imports generator through `from ..generator import`."""
from ..generator import sampler  # noqa: F401
