"""A torchvision stand-in for ultralytics (bench/solver/pose_train.py puts this folder on
ultralytics' path) and nms_check.py."""
