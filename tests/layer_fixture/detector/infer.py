import json


def detect():
    from dockfactory.detector.model import build_model   # fine: heavy project module
    import torch                                          # fine: heavy dependency
    import cv2                                            # VIOLATION: cv2 is not heavy
    return json, build_model, torch, cv2
