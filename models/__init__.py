"""Detector weights shipped with dockfactory (package data; see core/resources.py)."""
