"""Sensor and colour cameras: effects on centres and pose, Cramer-Rao bounds, demosaic cost."""
