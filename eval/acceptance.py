"""Acceptance spec (``configs/acceptance.toml``): what is gated, on which statistic, at what value.

Thresholds apply to the components named in each table (x, y, z in mm; alpha, beta, gamma in deg);
components not named are reported but not gated. With ``statistic = "rmse"`` (the default) a
threshold is in mm or deg; with ``statistic = "mse"`` it is in mm^2 or deg^2.
- estimation: repeatability, the pooled spread of repeated estimates of one static pose about
  that pose's mean (RMS deviation; its square for mse);
- localization: accuracy, the error of the estimate against the exact ground truth on the test
  split.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core.config import ConfigError, build_dataclass
from dockfactory.core.names import COMPONENTS, POSE_KEYS, UNITS  # noqa: F401  (re-exported)


@dataclass(frozen=True)
class Gate:
    statistic: str = "rmse"
    x: float = -1.0        # -1: not gated
    y: float = -1.0
    z: float = -1.0
    alpha: float = -1.0
    beta: float = -1.0
    gamma: float = -1.0

    def gated(self) -> dict[str, float]:
        return {c: getattr(self, c) for c in COMPONENTS if getattr(self, c) >= 0}


@dataclass(frozen=True)
class DetectionGate:
    map50_min: float = -1.0
    map50_95_min: float = -1.0


@dataclass(frozen=True)
class FailureGate:
    max_rate: float = 0.01
    conditions: tuple[str, ...] = ("normal",)   # failure rate is gated on these conditions


@dataclass(frozen=True)
class PaperFigures:
    """Values the paper reports (table 3), shown beside ours in the report."""
    estimation_x: float = 0.856
    estimation_y: float = 0.877
    estimation_alpha: float = 0.048
    localization_x: float = 0.794
    localization_y: float = 0.776
    localization_alpha: float = 0.869
    map50: float = 0.995
    map50_95: float = 0.834


@dataclass(frozen=True)
class AcceptanceSpec:
    estimation: Gate = field(default_factory=lambda: Gate(x=1.0, y=1.0, alpha=0.05))
    localization: Gate = field(default_factory=lambda: Gate(x=5.0, y=5.0, alpha=0.1))
    detection: DetectionGate = field(default_factory=DetectionGate)
    failures: FailureGate = field(default_factory=FailureGate)
    paper: PaperFigures = field(default_factory=PaperFigures)


def load_acceptance(path) -> AcceptanceSpec:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read acceptance spec: {exc.strerror}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc
    # a table that is given replaces the default gates wholesale: only what it names is gated
    spec = build_dataclass(AcceptanceSpec, data, str(path))
    for name in ("estimation", "localization"):
        gate = getattr(spec, name)
        if gate.statistic not in ("rmse", "mse"):
            raise ConfigError(f"{path}: [{name}] statistic: {gate.statistic!r} is not rmse or mse")
    if not 0 <= spec.failures.max_rate <= 1:
        raise ConfigError(f"{path}: [failures] max_rate: must be in [0, 1], got {spec.failures.max_rate}")
    for m in ("map50_min", "map50_95_min"):
        v = getattr(spec.detection, m)
        if v > 1:
            raise ConfigError(f"{path}: [detection] {m}: must be at most 1, got {v}")
    return spec
