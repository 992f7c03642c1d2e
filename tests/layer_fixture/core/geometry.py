"""Fine: stdlib and numpy at module level; a relative import of a sibling."""
import math

import numpy as np

from . import layout   # relative, same layer: fine (and core.layout imports nothing back)


def norm(v):
    return math.sqrt(float(np.dot(v, v))) + layout.RADIUS
