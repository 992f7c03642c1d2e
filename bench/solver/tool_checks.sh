#!/bin/sh
# The exports checked with the real tools that cannot be installed beside this project's torch or
# are not on PyPI: ultralytics (needs torchvision) and bop_toolkit (a GitHub checkout). The tests
# skip without them; this runs them and prints the tools' versions, for a committed record.
#
#   DOCKFACTORY_ULTRALYTICS=DIR  an unpacked `pip download ultralytics --no-deps` wheel
#   DOCKFACTORY_BOP_TOOLKIT=DIR  a bop_toolkit checkout; PYTHONPATH: its dependencies if not installed
#   sh bench/solver/tool_checks.sh > bench/results/tool_checks/<date>.txt
set -eu
cd "$(dirname "$0")/../.."
PY=.venv/bin/python
echo "# $(date -u +%Y-%m-%dT%H:%MZ) $(git rev-parse --short HEAD)"
echo "ultralytics: $(sed -n 's/^__version__ = "\(.*\)"/\1/p' "$DOCKFACTORY_ULTRALYTICS/ultralytics/__init__.py")"
echo "bop_toolkit: $(git -C "$DOCKFACTORY_BOP_TOOLKIT" rev-parse --short HEAD 2>/dev/null || cat "$DOCKFACTORY_BOP_TOOLKIT/COMMIT" 2>/dev/null || echo unknown)"
$PY -c "import pycocotools, numpy; print('numpy', numpy.__version__)"
$PY -m pytest -v -p no:xdist -p no:warnings -rs tests/generator/test_export_pose.py tests/generator/test_export_bop.py \
    tests/generator/test_coco_results.py 2>&1 | grep -E "PASSED|FAILED|SKIPPED|passed|failed"
