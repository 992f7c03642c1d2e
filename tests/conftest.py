import os
import shutil
from pathlib import Path

import pytest

import dockfactory

# the environment the command line runs in, set before any test module loads numpy (core/blas.py):
# tests render and compare label bytes in this process
dockfactory.set_app_environment(os.environ)

# the repository (configs, README); the code is imported as the installed `dockfactory` package
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


def write_config(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture
def tmp_config(tmp_path):
    def make(text: str, name: str = "cfg.toml") -> Path:
        return write_config(tmp_path / name, text)
    return make


os.environ.setdefault("HYPOTHESIS_PROFILE", "ci")

# Property tests draw their examples from a fixed seed by default, so a red CI run is
# reproducible and a green one stays green; HYPOTHESIS_PROFILE=explore draws fresh examples
# (and more of them) to hunt for new counter-examples locally.
from hypothesis import settings  # noqa: E402

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", max_examples=500, derandomize=False)
settings.load_profile(os.environ["HYPOTHESIS_PROFILE"])


@pytest.fixture(scope="session")
def painted_source(tmp_path_factory):
    """A complete smoke dataset written without Blender (tests/pipeline_data.py): read it only."""
    from pipeline_data import painted_copy

    from dockfactory.core.resources import shipped_config
    return painted_copy(tmp_path_factory, tmp_path_factory.mktemp("painted") / "dataset",
                        shipped_config("smoke").read_text())


@pytest.fixture
def painted(painted_source, tmp_path):
    """A private copy of the painted smoke dataset, free to damage."""
    root = tmp_path / "ds"
    shutil.copytree(painted_source, root)
    return root
