"""Detector: inference and training speed, mAP, box edges, centre bias."""
