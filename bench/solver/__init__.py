"""Solver: accuracy and honesty on synthetic geometry, speed, memory, bounds, tool checks."""
