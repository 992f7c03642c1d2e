"""Rendering and datasets: render cost and quality, label-aware sampling, re-render checks."""
