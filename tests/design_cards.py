"""A copy of the shipped design predictor's card with one optional section set or removed, for
tests of what that section does."""
from __future__ import annotations

import json

from dockfactory.core.resources import shipped_design_card
from dockfactory.eval.design_card import load_design_card


def card_with(tmp_path, key: str, value):
    """The shipped card with ``key`` set to ``value`` (None: removed), written under ``tmp_path``
    and loaded (DockfactoryError as load_design_card)."""
    data = json.loads(shipped_design_card().read_text())
    data.pop(key, None)
    if value is not None:
        data[key] = value
    path = tmp_path / f"card{len(list(tmp_path.iterdir()))}.json"
    path.write_text(json.dumps(data))
    return load_design_card(path)
