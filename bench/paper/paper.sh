#!/bin/sh
# The paper at full scale (issue 13): every command behind results/paper/, in order. Each step
# resumes where it stopped (the render renders only missing frames, training continues from the
# last epoch's checkpoint, ablate --record takes finished runs from results/paper/), so the whole
# script can be run again after any interruption.
#
#   sh bench/paper/paper.sh [render|render_sampled|publish|train|train_s|train_n|ship_s|accept|accept_s|accept_n|table1|table1_collect|summary|remeasure|all]
#
# Cost on the 2-core machine of 2026-12-01: render ~5.3 s/frame (3,200 frames, ~4.7 h; ~2.8 s/frame on an
# AVX-512 machine, re-rendered there on 2026-12-01 and checked by `publish`); YOLOv5s
# training ~13.8 crops/s (2,160 steps of 16 crops: ~42 min a run), YOLOv5n ~28 crops/s.
set -eu
DF=${DF:-.venv/bin/dockfactory}
PY=${PY:-.venv/bin/python}
DATA=${DATA:-out/paper}          # the dataset (large: kept out of git; its manifest is published)
RUNS=${RUNS:-out/paper_runs}     # checkpoints and weights of every training run
RES=${RES:-results/paper}   # the figures (another folder for a re-measure: results/paper is the published release's)
# budget of every run: 8 epochs x 2,160 train frames x 2 crops / batch 16 = 2,160 SGD steps, about
# the shipped n + SE recipe's 2,100 (70 epochs of the 239-frame detector.toml set)
TRAIN="--epochs 8 --batch 16 --crops-per-frame 2 --input-scale 0.5 --threads 2 --quiet"

render() {
    $DF render configs/paper.toml --out "$DATA" --workers 1
}

render_sampled() {  # the paper's frames with today's label-aware sampling (the published release pins it off;
                    # re-measure): DATA=out/paper_sampled RES=results/paper_sampled RUNS=out/paper_sampled_runs,
                    # then accept_s and summary with the same three
    $DF render configs/paper.toml --out "$DATA" --workers 2 --set render.marker_samples=40
}

publish() {  # the first render publishes its manifest; a re-render (later, or on another CPU) is
             # checked against the published one, never published over it
    if [ -f "$RES/manifest.json" ]; then
        $DF dataset verify "$DATA" --manifest "$RES/manifest.json"
    else
        $DF dataset verify "$DATA"
        $DF dataset publish "$DATA" --out "$RES"
    fi
}

train_s() {  # the paper's detector (Table 1's SE, seed 0)
    $DF ablate "$DATA" --model s --attention se --seeds 1 $TRAIN --out "$RUNS/s" --record "$RES/table1"
}

train_n() {  # ours: same recipe and budget
    $DF ablate "$DATA" --model n --attention se --seeds 1 $TRAIN --out "$RUNS/n" --record "$RES/n_se"
}

table1() {  # the five variants x three seeds (finished runs are taken from the records)
    $DF ablate "$DATA" --model s --attention none,se,eca,cbam,a2 --seeds 3 $TRAIN --out "$RUNS/s" \
        --record "$RES/table1"
    cp "$RUNS/s/ablation.md" "$RES/table1.md"
}

table1_collect() {  # the table of the runs finished so far, training nothing (safe beside a running
                    # table1); a record made before a figure was measured gets it from the saved detections
    $DF ablate "$DATA" --model s --attention none,se,eca,cbam,a2 --seeds 3 $TRAIN --out "$RUNS/s" \
        --record "$RES/table1" --no-train
    cp "$RUNS/s/ablation.md" "$RES/table1.md"
}

ship_s() {  # the paper's detector in fp16 beside the shipped n + SE (exits 1 if a quoted figure changes)
    $PY -m bench.detector.half_weights "$RUNS/s/se_seed0/weights.pt" models/yolov5s_se_markers.pt "$DATA" --threads 2
}

accept_one() {  # NAME WEIGHTS: detector figures and the full acceptance run with one detector
    name=$1 work="$RUNS/accept_$1"
    mkdir -p "$work" "$RES/$name"
    cp "$2" "$work/weights.pt"   # a copy: the noise card is written beside it, never over a shipped card
    weights="$work/weights.pt"
    $DF noise-card "$DATA" --weights "$weights" --threads 2 --quiet
    $PY -m bench.detector.detector_bench "$DATA" --weights "$weights" --threads 2 --train-batches 0 \
        --out "$RES/$name/detector.json"
    $PY -m bench.detector.detector_bench "$DATA" --weights "$weights" --threads 2 --train-batches 0 --split repeat \
        --images 1 --rounds 1 --out "$RES/$name/detector_repeat.json"
    $DF detect "$DATA" --weights "$weights" --split all --threads 2 --quiet --out "$work/detections.json"
    $DF solve "$DATA" --detections "$work/detections.json" --out "$work/poses.json"
    $DF evaluate "$DATA" --poses "$work/poses.json" --detections "$work/detections.json" --out "$work/eval" || [ $? -eq 1 ]   # 1: REJECTED, a result
    $DF report "$work/eval" --out "$RES/$name/report.html"
    cp "$work/eval/metrics.json" "$RES/$name/metrics.json"
}

accept_s() { accept_one s_se models/yolov5s_se_markers.pt; }   # the shipped file (after ship_s)
accept_n() { accept_one n_se "$RUNS/n/se_seed0/weights.pt"; }

summary() {  # the detectors whose acceptance run finished (a re-measure may have only s_se)
    dets=""
    [ -f "$RES/s_se/detector.json" ] && dets="$dets --detector s_se=$RES/s_se:$RES/s_se/detector.json:models/yolov5s_se_markers.pt"
    [ -f "$RES/n_se/detector.json" ] && dets="$dets --detector n_se=$RES/n_se:$RES/n_se/detector.json:$RUNS/n/se_seed0/weights.pt"
    # shellcheck disable=SC2086   # $dets: words on purpose (paths without spaces)
    $PY -m bench.paper.paper_results --dataset "$DATA" --out "$RES" --table1 "$RES/table1" --published "$RES/manifest.json" $dets
}

remeasure() {  # the paper at today's sampling, end to end and resumable: DATA, RES, RUNS as render_sampled says
    render_sampled; publish; accept_s; summary
}

case "${1:-all}" in
    render) render ;;
    render_sampled) render_sampled ;;
    publish) publish ;;
    train) train_s; train_n ;;
    train_s) train_s ;;
    train_n) train_n ;;
    ship_s) ship_s ;;
    table1) table1 ;;
    table1_collect) table1_collect ;;
    accept) accept_s; accept_n ;;
    accept_s) accept_s ;;
    accept_n) accept_n ;;
    summary) summary ;;
    remeasure) remeasure ;;
    all) render; publish; train_s; train_n; ship_s; accept_s; accept_n; table1; summary ;;
    *) echo "usage: sh bench/paper/paper.sh [render|render_sampled|publish|train|train_s|train_n|ship_s|accept|accept_s|accept_n|table1|table1_collect|summary|remeasure|all]" >&2; exit 2 ;;
esac
