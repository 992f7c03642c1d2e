"""The judge: metrics of poses and detections against a dataset's labels, the acceptance verdict
and its spec, the frames a verdict needs, and the detector's noise card, behind a small facade.

Modules: :mod:`~dockfactory.eval.evaluate` (an evaluation: metrics, verdict, outputs; its
``evaluate`` is the facade's ``evaluate_poses``, so the module keeps its name),
``solve_frames`` (every frame of a dataset solved), ``acceptance`` (the spec and the verdict's exit
status), ``frame_planner`` (frames needed), ``conformity`` (ISO 14253-1 decisions),
``detection_metrics`` (COCO and YOLOv5 mAP, centre errors), ``noise_calibration`` (the weights'
noise card); the report in :mod:`~dockfactory.eval.report`. Importing the package loads no torch.
"""
from dockfactory.eval.acceptance import AcceptanceSpec, load_acceptance, verdict_exit_status
from dockfactory.eval.conformity import pose_conformity
from dockfactory.eval.detection_metrics import evaluate_detections
from dockfactory.eval.evaluate import evaluate as evaluate_poses
from dockfactory.eval.evaluate import write_outputs
from dockfactory.eval.frame_planner import plan_frames
from dockfactory.eval.noise_calibration import calibrate_noise_card
from dockfactory.eval.solve_frames import solve_dataset, write_poses

__all__ = [
    # poses of a dataset, and their evaluation against its labels and a spec
    "solve_dataset", "write_poses", "evaluate_poses", "write_outputs",
    # the acceptance spec, the verdict's exit status, one pose's conformity, frames needed
    "load_acceptance", "AcceptanceSpec", "verdict_exit_status", "pose_conformity", "plan_frames",
    # the detector's figures
    "evaluate_detections", "calibrate_noise_card",
]
