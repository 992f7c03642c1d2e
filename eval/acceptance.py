"""Acceptance spec (``configs/acceptance.toml``): what is gated, on which statistic, at what value.

Thresholds apply to the components named in each table (x, y, z in mm; alpha, beta, gamma in deg); components not
named are reported but not gated: leaving a component out is the one way to ungate it. A threshold that is given
must be a finite number > 0 (NaN, inf, zero and negative values are refused, never read as "not gated"). A table
that is given must gate at least one component, or say ``gated = false`` (and then name no threshold): an empty
``[estimation]`` table, or one with only a statistic, would otherwise switch the gate off without a word. Detection
minima are in (0, 1]; ``[failures] max_rate`` is in [0, 1] and its ``conditions`` are names from
``core.config.CONDITIONS`` (case matters: "Normal" is refused), at least one, each once. A table's ``statistic``
is a name of ``eval.gate_statistic.STATISTICS`` ("rmse", the default, in mm or deg; each states its unit, its value,
its bounds and its conversion to the RMS there), and its thresholds are in that statistic's unit; a statistic that
cannot gate the table is refused in one line.
- estimation: repeatability, the spread of repeated estimates of one static pose about that pose's mean;
- localization: accuracy, the error of the estimate against the exact ground truth on the test split.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.eval.gate_statistic import STATISTICS, gate_statistic
from dockfactory.core.config import CONDITIONS, ConfigError, build_dataclass
from dockfactory.core.names import COMPONENTS, POSE_KEYS, UNITS  # noqa: F401  (re-exported)
from dockfactory.core.user_files import check_regular_file


@dataclass(frozen=True)
class Gate:
    statistic: str = "rmse"
    gated: bool = True     # false: the table is reported only (it must then name no threshold)
    x: float | None = None   # None: not gated (the default of a component a spec leaves out)
    y: float | None = None
    z: float | None = None
    alpha: float | None = None
    beta: float | None = None
    gamma: float | None = None

    def thresholds(self) -> dict[str, float]:
        """Component -> threshold of every gated component (none when ``gated`` is false)."""
        if not self.gated:
            return {}
        return {c: getattr(self, c) for c in COMPONENTS if getattr(self, c) is not None}


@dataclass(frozen=True)
class DetectionGate:
    map50_min: float | None = None      # None: not gated (mAP is reported only)
    map50_95_min: float | None = None


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


DECISION_RULES = ("guarded", "simple")
EXIT_NOT_PROVEN = 3   # exit status of evaluate / run when the guarded rule cannot decide


@dataclass(frozen=True)
class AcceptanceSpec:
    decision_rule: str = "guarded"   # guarded: the confidence bound decides (ISO 14253-1); simple: the value
    confidence: float = 0.95         # of each one-sided bound of a gated statistic
    estimation: Gate = field(default_factory=lambda: Gate(x=1.0, y=1.0, alpha=0.05))
    localization: Gate = field(default_factory=lambda: Gate(x=5.0, y=5.0, alpha=0.1))
    detection: DetectionGate = field(default_factory=DetectionGate)
    failures: FailureGate = field(default_factory=FailureGate)
    paper: PaperFigures = field(default_factory=PaperFigures)


def load_acceptance(path) -> AcceptanceSpec:
    """Read and check an acceptance spec (TOML, never executed; docs/acceptance.md).

    Parameters
    ----------
    path : str or Path
        The spec file; a table it gives replaces the default gates wholesale.

    Returns
    -------
    AcceptanceSpec

    Raises
    ------
    ConfigError
        A missing, unreadable, non-UTF-8 or invalid file, or a bad key or value (one line naming
        the file, table and key).
    """
    path = Path(path)
    check_regular_file(path, "acceptance spec")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read acceptance spec: {exc.strerror}") from exc
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: acceptance spec is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML: its arrays or tables nest too deeply") from None
    # a table that is given replaces the default gates wholesale: only what it names is gated
    spec = build_dataclass(AcceptanceSpec, data, str(path))
    validate_acceptance(spec, data, str(path))
    return spec


def _bad(source: str, table: str, key: str, msg: str) -> ConfigError:
    return ConfigError(f"{source}: [{table}] {key}: {msg}")


def _check_gates_something(source: str, name: str, gate: Gate, data: dict) -> None:
    """A table given in the file gates a component, or says ``gated = false`` and names none."""
    named = [c for c in COMPONENTS if c in data.get(name, {})]
    if gate.gated and name in data and not named:
        raise _bad(source, name, "thresholds", f"the table gates nothing (no {', '.join(COMPONENTS)}); give a "
                   "threshold, or write gated = false to report the table without gating it")
    if not gate.gated and named:
        raise _bad(source, name, "gated", f"false, yet the table gives thresholds for {', '.join(named)}")


def ungated_components(spec: AcceptanceSpec) -> list[str]:
    """What the spec reports without gating: pose components and detection minima it leaves out."""
    out = [f"{name}: {c}" for name in ("estimation", "localization")
           for c in COMPONENTS if c not in getattr(spec, name).thresholds()]
    out += [f"detection: {m[:-4]}" for m in ("map50_min", "map50_95_min") if getattr(spec.detection, m) is None]
    return out


def validate_acceptance(spec: AcceptanceSpec, data: dict, source: str) -> None:
    """Refuse a spec that would switch a gate off by accident. ``data``: the TOML tables as read
    (a component the file names must carry a real threshold; one it leaves out is not gated)."""
    if spec.decision_rule not in DECISION_RULES:
        raise ConfigError(f"{source}: decision_rule: {spec.decision_rule!r} is not one of {', '.join(DECISION_RULES)}")
    if not (math.isfinite(spec.confidence) and 0.5 <= spec.confidence < 1):
        raise ConfigError(f"{source}: confidence: must be in [0.5, 1), got {spec.confidence}")
    for name in ("estimation", "localization"):
        gate = getattr(spec, name)
        if gate.statistic not in STATISTICS:
            raise _bad(source, name, "statistic", f"{gate.statistic!r} is not one of {', '.join(STATISTICS)}")
        if why := gate_statistic(gate.statistic).refusal(name):
            raise _bad(source, name, "statistic", f"{gate.statistic!r}: {why}")
        given = data.get(name, {})
        _check_gates_something(source, name, gate, data)
        for c in COMPONENTS:
            if c in given:
                v = getattr(gate, c)
                if not math.isfinite(v) or v <= 0:
                    raise _bad(source, name, c, f"a threshold must be a finite number > 0, got {v} "
                               "(leave the component out to report it without gating it)")
    given = data.get("detection", {})
    for m in ("map50_min", "map50_95_min"):
        v = getattr(spec.detection, m)
        if m in given and not (math.isfinite(v) and 0 < v <= 1):
            raise _bad(source, "detection", m, f"must be in (0, 1], got {v} "
                       "(leave it out to report mAP without gating it)")
    f = spec.failures
    if not (math.isfinite(f.max_rate) and 0 <= f.max_rate <= 1):
        raise _bad(source, "failures", "max_rate", f"must be in [0, 1], got {f.max_rate}")
    if not f.conditions:
        raise _bad(source, "failures", "conditions", f"name at least one of {', '.join(CONDITIONS)}")
    for c in f.conditions:
        if c not in CONDITIONS:
            hint = f" (did you mean {c.lower()!r}?)" if c.lower() in CONDITIONS else ""
            raise _bad(source, "failures", "conditions", f"{c!r} is not a condition{hint}; "
                       f"known: {', '.join(CONDITIONS)}")
    if len(set(f.conditions)) != len(f.conditions):
        raise _bad(source, "failures", "conditions", f"a condition is listed twice: {list(f.conditions)}")
    for k in PaperFigures.__dataclass_fields__:
        v = getattr(spec.paper, k)
        if not (math.isfinite(v) and v >= 0):
            raise _bad(source, "paper", k, f"must be a finite number >= 0, got {v}")


# ----------------------------------------------------------------------------- the verdict

def _without_pose(block: dict) -> tuple[int, int | None]:
    """(frames without a pose, frames) of a localization / estimation block (0, None when the
    block does not say)."""
    n, solved = block.get("n_frames"), block.get("n_solved")
    if n is None or solved is None:
        return 0, None
    return n - solved, n


POSE_BLOCKS = (("estimation", "estimation precision (repeatability)", "captures"),
               ("localization", "localization precision (accuracy)", "test frames"))


def _pose_criteria(metrics: dict, spec: AcceptanceSpec) -> list[dict]:
    """One criterion per gated pose component of estimation and localization, decided by the
    spec's rule on the statistic's confidence bounds (``metrics["bounds"]``)."""
    criteria = []
    for block, label, what in POSE_BLOCKS:
        gate, blk = getattr(spec, block), metrics[block]
        lacking, n = _without_pose(blk)
        for c, thr in gate.thresholds().items():
            stat = (blk["pooled"] if block == "estimation" else blk["overall"])[c][gate.statistic]
            note = ""
            if lacking:
                stat, note = None, f"{lacking} of {n} {what} without a pose"
            elif stat is None:
                note = ("no pose captured twice" if block == "estimation" else "no test frame") + ": nothing to measure"
            unit = gate_statistic(gate.statistic).unit(UNITS[c])
            row = {"name": f"{label}: {c}", "block": block, "component": c, "statistic": gate.statistic,
                   "value": stat, "threshold": thr, "unit": unit, "note": note,
                   "paper": getattr(spec.paper, f"{block}_{c}", None)}
            row.update(_bounds_of(metrics, block, c, gate.statistic, stat))
            row["decision"] = decide_criterion(spec.decision_rule, stat, thr, row["lower"], row["upper"])
            row["pass"] = row["decision"] == "pass"
            if row["decision"] == "undecided":
                row["note"] = _more_frames_note(blk, c, stat, thr, gate.statistic, spec.confidence, block)
            criteria.append(row)
    return criteria


def _more_frames_note(blk: dict, c: str, value: float, thr: float, statistic: str, confidence: float,
                      block: str) -> str:
    """What would decide an undecided criterion: how many more frames (captures) the statistic's
    bound needs if the measured value holds (eval.gate_statistic ``frames_to_decide``)."""
    stat = gate_statistic(statistic)
    dof = blk.get("dof") if block == "estimation" else blk["overall"][c].get("n")
    needed = stat.frames_to_decide(stat.to_rms(value), stat.to_rms(thr), int(dof or 0), confidence)
    what = "repeatability captures" if block == "estimation" else "test frames"
    if needed is None:
        return f"undecided: the value sits at the threshold; no number of {what} decides it"
    return (f"undecided: about {max(0, needed - int(dof))} more {what} would decide it, if the measured "
            f"value holds")


def _bounds_of(metrics: dict, block: str, c: str, statistic: str, value) -> dict:
    """The statistic's lower and upper confidence bounds in its own units (eval.gate_statistic
    ``own_bounds``: squared for mse) and their methods; none without a value or an upper bound (a
    guarded criterion then fails), with the record's note on why a bound is missing."""
    b = ((metrics.get("bounds") or {}).get(block) or {}).get(c) or {}
    if value is None or b.get("upper") is None:
        why = {"note": b["note"]} if value is not None and b.get("note") else {}
        return {"lower": None, "upper": None, "bounds_by": None, **why}
    lower, upper = gate_statistic(statistic).own_bounds(b)
    tails = (f"; heavy tails (kurtosis {b['kurtosis']:.1f}): the upper bound may undercover"
             if b.get("heavy_tailed") else "")
    return {"lower": lower, "upper": upper, "bounds_by": f"{b['lower_by']} / {b['upper_by']}{tails}"}


def decide_criterion(rule: str, value, threshold, lower, upper) -> str:
    """"pass", "fail" or "undecided" of a "max" criterion. simple: the value against the
    threshold. guarded (ISO 14253-1): pass only when the upper bound is within the threshold,
    fail when the lower bound is beyond it, undecided between; no value or no bound fails."""
    if rule == "simple":
        return "pass" if criterion_passes("max", value, threshold) else "fail"
    if value is None or lower is None or upper is None:
        return "fail"
    if criterion_passes("max", upper, threshold):
        return "pass"
    return "fail" if not criterion_passes("max", lower, threshold) else "undecided"


def _detection_criteria(metrics: dict, spec: AcceptanceSpec) -> list[dict]:
    det, out = metrics.get("detection") or {}, []
    for key, thr, paper in (("map50", spec.detection.map50_min, spec.paper.map50),
                            ("map50_95", spec.detection.map50_95_min, spec.paper.map50_95)):
        if thr is not None:
            v = det.get(key)
            out.append({"name": f"detection: {key}", "block": "detection", "component": key, "statistic": "min",
                        "value": v, "threshold": thr, "unit": "", "note": "" if v is not None else "no detections",
                        "pass": criterion_passes("min", v, thr), "paper": paper})
    return out


def _failure_criterion(metrics: dict, spec: AcceptanceSpec) -> dict:
    n_fail = n = 0
    for block in ("failures_test", "failures_repeat"):
        f = (metrics.get(block) or {}).get("by_condition", {})
        n_fail += sum(f[c]["failed"] for c in spec.failures.conditions if c in f)
        n += sum(f[c]["frames"] for c in spec.failures.conditions if c in f)
    rate = n_fail / n if n else None
    return {"name": f"failure rate ({', '.join(spec.failures.conditions)})", "block": "failures",
            "component": "rate", "statistic": "max", "value": rate, "threshold": spec.failures.max_rate,
            "unit": "", "note": f"{n_fail} of {n} test frames and repeatability captures" if n else
            "no test frame or repeatability capture of these conditions",
            "pass": criterion_passes("max", rate, spec.failures.max_rate), "paper": None}


def verdict(metrics: dict, spec: AcceptanceSpec) -> dict:
    """The acceptance criteria and the verdict (accepted: every criterion passes).

    Monotone by construction: a frame that fails or disappears can only turn a criterion from pass
    to fail, never the other way.
    - A gated pose statistic is defined only over its whole population (localization: every
      planned test frame; estimation: every planned repeatability capture). If any frame of it has
      no pose (failed, absent from the poses file or from the dataset) the statistic has no value
      and the criterion fails, with a note saying how many frames lack a pose; a statistic over
      zero frames (or a spread with no degree of freedom) fails too.
    - The failure rate covers the test frames and the repeatability captures of the listed
      conditions; over zero such frames it has no value and fails.
    - Pose criteria follow the spec's decision rule (:func:`decide_criterion`) on the statistic's
      one-sided confidence bounds (eval.confidence); detection minima and the failure rate
      compare the value itself.
    Every criterion's decision follows from the numbers in its row, so the rows a report prints
    determine the verdict. ``ungated`` lists what the spec reports without
    gating (:func:`ungated_components`), so a reader sees what the verdict does not cover.
    """
    criteria = _pose_criteria(metrics, spec) + _detection_criteria(metrics, spec) + [_failure_criterion(metrics, spec)]
    return {"accepted": all(c["pass"] for c in criteria), "verdict": overall_verdict(criteria),
            "decision_rule": spec.decision_rule, "confidence": spec.confidence, "criteria": criteria,
            "ungated": ungated_components(spec)}


def overall_verdict(criteria: list[dict]) -> str:
    """ACCEPTED when every criterion passes, REJECTED when one fails, NOT PROVEN when none fails
    but some could not be decided (the guarded rule: more frames would decide)."""
    decisions = [c.get("decision", "pass" if c["pass"] else "fail") for c in criteria]
    if all(d == "pass" for d in decisions):
        return "ACCEPTED"
    return "REJECTED" if "fail" in decisions else "NOT PROVEN"


def verdict_exit_status(verdict_text: str) -> int:
    """The exit status of a verdict.

    Parameters
    ----------
    verdict_text : str
        ``ACCEPTED``, ``REJECTED`` or ``NOT PROVEN``.

    Returns
    -------
    int
        0 ACCEPTED, 1 REJECTED, EXIT_NOT_PROVEN (3) for NOT PROVEN (and anything else).
    """
    return {"ACCEPTED": 0, "REJECTED": 1}.get(verdict_text, EXIT_NOT_PROVEN)


def criterion_passes(statistic: str, value, threshold) -> bool:
    """A criterion's result from its value and threshold: "min" needs value >= threshold, every
    other statistic value <= threshold; no value (None, NaN) fails."""
    if value is None or threshold is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    if not (math.isfinite(value) and math.isfinite(threshold)):
        return False
    return bool(value >= threshold) if statistic == "min" else bool(value <= threshold)


def _num(v) -> str:
    return "-" if v is None else f"{v:.4g}"


def criterion_lines(acc: dict) -> list[str]:
    """One line per criterion for a terminal: decision, name, value (with its bounds under the
    guarded rule), threshold, note."""
    out = []
    for c in acc["criteria"]:
        decision = c.get("decision", "pass" if c["pass"] else "fail").upper()
        bounds = (f" ({acc.get('confidence', 0.95):.0%} bounds {_num(c['lower'])}-{_num(c['upper'])})"
                  if c.get("upper") is not None else "")
        note = f" [{c['note']}]" if c.get("note") else ""
        out.append(f"{decision:9s} {c['name']}: {_num(c['value'])}{bounds} (threshold {_num(c['threshold'])} "
                   f"{c['unit']}){note}")
    return out
