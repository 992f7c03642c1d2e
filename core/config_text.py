"""Configs as text: TOML written back from the schema's data, ``--set TABLE.KEY=VALUE`` overrides,
the defaults with their meanings, and the key reference (docs/config_reference.md).

The schema is ``core.config.Config``: its tables are frozen dataclasses, each key a typed field
with a default; a key's meaning is the comment beside its field in core/config.py (read from the
source, so the reference cannot drift from the code: tests/contracts/test_docs.py regenerates it).
"""
from __future__ import annotations

import dataclasses
import io
import json
import math
import tokenize
import tomllib
import typing
from pathlib import Path

from dockfactory.core import config as config_mod
from dockfactory.core.config import Config, ConfigError, config_from_dict
from dockfactory.core.config_files import resolve_config_files
from dockfactory.core.user_files import check_regular_file


def toml_value(value) -> str:
    """One TOML value: booleans, integers, floats (always with a point or exponent), strings
    (JSON escapes are TOML's), lists (nested)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"a config holds finite numbers only, got {value}")
        text = repr(value)
        return text if any(c in text for c in ".eE") else text + ".0"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML for {type(value).__name__}")   # programming error


def to_toml(data: dict) -> str:
    """TOML text of a config's data (tables of keys; ``[sensor] overrides`` as a sub-table),
    which ``tomllib`` reads back to the same config."""
    out = []
    for table, keys in data.items():
        out.append(f"[{table}]")
        nested = []
        for key, value in keys.items():
            if isinstance(value, dict):
                nested.append((key, value))
            elif key == "overrides" and isinstance(value, (list, tuple)):
                nested.append((key, dict(value)))
            else:
                out.append(f"{key} = {toml_value(value)}")
        for key, sub in nested:
            out += [f"[{table}.{key}]"] + [f"{k} = {toml_value(v)}" for k, v in sub.items()]
        out.append("")
    return "\n".join(out)


def apply_overrides(data: dict, sets, source: str) -> dict:
    """``data`` (a config's TOML tables) with each ``TABLE.KEY=VALUE`` of ``sets`` applied. VALUE
    is read as a TOML value (``10``, ``[1.0, 2.0]``, ``"text"``); a bare word that is not one is
    taken as a string. ConfigError naming the override when it is malformed; the merged data is
    then validated like a file (unknown keys, types and ranges)."""
    merged = json.loads(json.dumps(data))
    for item in sets or ():
        key, eq, text = item.partition("=")
        parts = key.strip().split(".")
        if not eq or len(parts) < 2 or not all(parts):
            raise ConfigError(f"--set {item!r}: expected TABLE.KEY=VALUE (e.g. dataset.frames=10)")
        bad = next((c for c in item if ord(c) < 0x20 or ord(c) == 0x7F), None)
        if bad is not None:
            raise ConfigError(f"--set {item!r}: control character {bad!r} (a newline, a tab, ...): "
                              "one line of printable text expected")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        except RecursionError:
            raise ConfigError(f"--set {item[:60]!r}...: its value nests too deeply") from None
        node = merged
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ConfigError(f"--set {item!r}: {p} is a key, not a table")
        node[parts[-1]] = value
    return merged


def load_config_text(path, sets=()) -> tuple[Config, str]:
    """(config, its text) of the TOML file ``path`` with ``--set`` overrides ``sets`` applied and
    its calibration file resolved (core.config_calibration): the text is the file's own without
    either, else the resolved TOML (so a dataset's config.toml always reproduces it).
    ConfigError or CalibrationError (file, key, value) on any problem."""
    path = Path(path)
    check_regular_file(path, "config")
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a TOML config: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML: its arrays or tables nest too deeply") from None
    merged = apply_overrides(data, sets, str(path)) if sets else data
    merged, note = resolve_config_files(merged, path)
    if not sets and note is None:
        return config_from_dict(data, str(path)), text
    changes = " and ".join(c for c in (f"--set {' '.join(sets)}" if sets else "", note) if c)
    cfg = config_from_dict(merged, f"{path} with {changes}")
    return cfg, f"# {path.name} with {changes}\n" + to_toml(cfg.resolved_dict())


# ----------------------------------------------------------------------------- the reference

def field_comments() -> dict[tuple[str, str], str]:
    """(dataclass name, field name) -> the comment beside the field in core/config.py."""
    source = Path(config_mod.__file__).read_text(encoding="utf-8")
    out, cls, pending = {}, None, None
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NAME and tok.start[1] == 0:
            cls = None
        if tok.type == tokenize.NAME and tok.string == "class" and tok.start[1] == 0:
            pending = "class"
        elif pending == "class" and tok.type == tokenize.NAME:
            cls, pending = tok.string, None
        elif cls and tok.type == tokenize.NAME and tok.start[1] == 4 and pending is None:
            pending = ("field", tok.string, tok.start[0])
        elif isinstance(pending, tuple) and tok.type == tokenize.COMMENT and tok.start[0] == pending[2]:
            out[(cls, pending[1])] = tok.string.lstrip("# ").strip()
        if tok.type == tokenize.NEWLINE:
            pending = None if pending != "class" else pending
    return out


def type_text(hint) -> str:
    """A field's type in words."""
    if hint == config_mod.Overrides:
        return "table of name = number"
    if hint == config_mod.Range:
        return "[min, max]"
    if hint == (float | None):   # TOML has no null: the key is a number or left out
        return "number"
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {type_text(args[0])}"
        return "[" + ", ".join(type_text(a) for a in args) + "]"
    return {bool: "bool", int: "integer", float: "number", str: "string"}.get(hint, str(hint))


TYPE_WORDS = {("markers", "layout_a"): "list of [s_mm, phi_deg]", ("markers", "layout_b"): "list of [s_mm, phi_deg]",
              ("camera_units", "jpeg_quality"): "[min, max] integers", ("occlusion", "occluders"): "[min, max] integers"}


def tables():
    """(table name, dataclass, [(key, type text, default TOML, meaning)]) of the schema."""
    comments = field_comments()
    defaults = Config().to_dict(full=True)
    for f in dataclasses.fields(Config):
        cls = typing.get_type_hints(Config)[f.name]
        hints = typing.get_type_hints(cls)
        rows = [(k.name, TYPE_WORDS.get((f.name, k.name)) or type_text(hints[k.name]),
                 _default_text(defaults[f.name][k.name]),
                 comments.get((cls.__name__, k.name), "")) for k in dataclasses.fields(cls)]
        yield f.name, cls, rows


def _default_text(value) -> str:
    return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value) + " }" \
        if isinstance(value, list) and value and isinstance(value[0], list) and len(value[0]) == 2 \
        and isinstance(value[0][0], str) else toml_value(value)


def defaults_toml() -> str:
    """Every table and key with its default, type and meaning as comments: a config to copy."""
    out = ["# dockfactory config: every key with its default (dockfactory check-config --defaults).",
           "# A config names only what differs; see docs/config_reference.md.", ""]
    for name, cls, rows in tables():
        if cls.__doc__ and not cls.__doc__.startswith(cls.__name__ + "("):
            out.append("# " + " ".join(cls.__doc__.split()))
        out.append(f"[{name}]")
        for key, kind, default, meaning in rows:
            out.append(f"{key} = {default}  # {kind}" + (f"; {meaning}" if meaning else ""))
        out.append("")
    return "\n".join(out)


LIMITS = ("MAX_FRAMES", "MAX_REPEAT_POSES", "MAX_REPEAT_CAPTURES", "MIN_IMAGE_PX", "MAX_IMAGE_PX", "MAX_SAMPLES",
          "MAX_BOUNCES", "MAX_MAGNITUDE", "MAX_CAMERA_UNITS", "MAX_PRINCIPAL_OFFSET", "MAX_RADIAL",
          "MAX_TANGENTIAL", "MAX_ABERRATION_PX", "MAX_PIXEL_ASPECT_DIFF", "F_NUMBER_LIMITS", "SENSOR_WIDTH_LIMITS_MM",
          "MAX_SPEED_MM_S", "MAX_READOUT_MS")


def reference_markdown() -> str:
    """docs/config_reference.md: every table and key (type, default, meaning) and the limits."""
    out = ["# Config key reference", "",
           "Generated from the schema (`core/config.py`) by `core/config_text.py`; `dockfactory check-config "
           "--defaults` prints the same as a TOML file to copy. Do not edit by hand: tests/contracts/test_docs.py "
           "fails when this page and the schema drift.", "",
           "Every key has a default; a config names only what differs. Unknown keys, wrong types and impossible "
           "values are refused in one line naming the file, table and key. Ranges are `[min, max]` with "
           "min <= max; every number is finite. Per-unit lists give camera unit u its item u % len(list).", ""]
    for name, cls, rows in tables():
        out += [f"## [{name}]", ""]
        if cls.__doc__ and not cls.__doc__.startswith(cls.__name__ + "("):
            out += [" ".join(cls.__doc__.split()), ""]
        out += ["| key | type | default | meaning |", "| --- | --- | --- | --- |"]
        out += [f"| `{k}` | {t} | `{d}` | {m.replace('|', '/')} |" for k, t, d, m in rows]
        out.append("")
    out += ["## Limits", "", "Named bounds every config is checked against (`core/config.py`):", "",
            "| name | value |", "| --- | --- |"]
    out += [f"| `{n}` | `{getattr(config_mod, n)}` |" for n in LIMITS]
    return "\n".join(out) + "\n"
