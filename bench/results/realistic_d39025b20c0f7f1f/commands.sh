set -x
cd /work/main
D=out/realistic; E=out/realistic_eval
.venv/bin/dockfactory dataset verify $D | head -3
.venv/bin/dockfactory detect $D --split all --out $E/dets.json --threads 2 --quiet --eval
.venv/bin/dockfactory solve $D --detections $E/dets.json --out $E/poses_pinhole.json
.venv/bin/dockfactory solve $D --detections $E/dets.json --self-calibrate sequence --split test --out $E/poses_sequence.json
.venv/bin/dockfactory evaluate $D --poses $E/poses_pinhole.json --detections $E/dets.json --camera-models --envelope --out $E/eval
.venv/bin/dockfactory report $E/eval --out $E/report.html
.venv/bin/dockfactory solve $D --oracle-noise 0.1 --out $E/poses_oracle.json
.venv/bin/dockfactory evaluate $D --poses $E/poses_oracle.json --camera-models --out $E/eval_oracle
ls $D/images > /dev/null
.venv/bin/dockfactory measure $(.venv/bin/python -c "
from dockfactory.generator.datasets.reader import Dataset
ds=Dataset.open('$D', full=False); print(' '.join(str(ds.image_path(f)) for f in ds.frames('test')))") --layout $D/layout.json --out $E/measure --threads 2 --quiet
echo DONE
