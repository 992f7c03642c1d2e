"""Files shipped inside the package (configs, detector weights), read through importlib.resources,
so an installed dockfactory finds them wherever it is installed and whatever the working folder."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.user_files import check_regular_file

WEIGHTS_NAME = "yolov5n_se_rings_markers.pt"   # the default detector (model card: models/README.md)
ACCEPTANCE_NAME = "acceptance.toml"
DESIGN_CARD_NAME = "design_predictor.json"   # the design predictor's card (bench/design/design_fit.py)
DESIGN_REFUSALS_NAME = "design_refusals.json"   # the figures design simulates refusals with (eval.design_card.with_refusals)


def _shipped(package: str, name: str) -> Path:
    path = Path(str(resources.files(package).joinpath(name)))
    if not path.is_file():
        raise DockfactoryError(f"{name}: not shipped with this dockfactory install ({package})")
    return path


def shipped_configs() -> tuple[str, ...]:
    """Names (without .toml) of the configs shipped with the package."""
    folder = resources.files("dockfactory.configs")
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml")))


def shipped_dataset_configs() -> tuple[str, ...]:
    """Names of the shipped configs that render a dataset (the acceptance spec is not one)."""
    return tuple(n for n in shipped_configs() if n != "acceptance")


def shipped_config(name: str) -> Path:
    """Path of a shipped config, by name (``quick`` or ``quick.toml``)."""
    stem = name[:-5] if name.endswith(".toml") else name
    return _shipped("dockfactory.configs", stem + ".toml")


def shipped_weights() -> Path:
    """Path of the shipped detector weights."""
    return _shipped("dockfactory.models", WEIGHTS_NAME)


def shipped_design_card() -> Path:
    """Path of the design predictor's card (eval.design_card)."""
    return _shipped("dockfactory.models", DESIGN_CARD_NAME)


def shipped_design_refusals() -> Path:
    """Path of the figures ``dockfactory design`` simulates frames without a pose with (unless --no-refusals)."""
    return _shipped("dockfactory.models", DESIGN_REFUSALS_NAME)


def resolve_design_space(arg: str | Path) -> Path:
    """A design space given on the command line: an existing file, else a shipped one named by
    ``NAME`` or ``NAME.toml`` (configs/designs/). DockfactoryError (one line) when there is none."""
    path = Path(arg)
    if path.is_file():
        return path
    stem = path.name[:-5] if path.name.endswith(".toml") else path.name
    try:
        return _shipped("dockfactory.configs", f"designs/{stem}.toml")
    except DockfactoryError:
        raise DockfactoryError(f"{arg}: no such design space file (nor a shipped one: "
                               f"configs/designs/)") from None


def default_acceptance() -> Path:
    """Path of the shipped acceptance spec (the paper's criteria)."""
    return _shipped("dockfactory.configs", ACCEPTANCE_NAME)


def resolve_config(arg: str | Path) -> Path:
    """A config given on the command line: an existing file, else a shipped config named by
    ``NAME``, ``NAME.toml`` or ``configs/NAME.toml`` (so the README's commands work from any
    folder). DockfactoryError (one line) for a folder, a fifo or a device, or no such config; the
    file's text is checked where it is read (core.config_text.load_config_text)."""
    path = Path(arg)
    if path.is_file():
        return path
    known = shipped_configs()
    stem = path.name[:-5] if path.name.endswith(".toml") else path.name
    if stem in known and path.parent in (Path("."), Path("configs")):
        return shipped_config(stem)   # a name (even beside a folder of that name, e.g. detector/)
    if path.is_dir():
        raise DockfactoryError(f"{arg}: is a folder, not a config file (give the .toml file)")
    check_regular_file(path, "config")
    raise DockfactoryError(f"{arg}: no such config file (shipped configs: {', '.join(known)})")
