#!/usr/bin/env bash
# Re-trains the default models shipped in models/ (see models/MODEL_CARD.md for the data,
# licences, times and metrics of the shipped run). CPU is enough: on 2 cores the whole
# script takes about two hours. Every training step is resumable: run the script again
# after a kill and each stage continues from its last checkpoint (--resume).
#
#   bash models/train_default_models.sh [DATASETS_DIR] [WORK_DIR]
#
# DATASETS_DIR holds the archives described in ../shared/datasets/README.md (default
# ../shared/datasets); WORK_DIR receives the prepared data and the runs (default runs/).
# The acRNN archive is prepared separately and kept out of training: it is the "never seen"
# dataset of the tokenizer's reconstruction report.
set -euo pipefail

DATA=${1:-../shared/datasets}
WORK=${2:-runs}
PREPARED=$WORK/prepared
UNSEEN=$WORK/prepared_acrnn
mkdir -p "$WORK"

if [ ! -f "$PREPARED/index.jsonl" ]; then
  motok-robot data prepare \
    --source bandai="$DATA/bandai-namco-bvh.tar.xz" \
    --source cmu="$DATA/cmu-asf-amc.tar.xz" \
    --source deepmimic="$DATA/deepmimic.tar.xz" \
    --out "$PREPARED"
fi
if [ ! -f "$UNSEEN/index.jsonl" ] && [ -f "$DATA/acrnn-bvh.tar.xz" ]; then
  motok-robot data prepare --source acrnn="$DATA/acrnn-bvh.tar.xz" --out "$UNSEEN"
fi

# resume a run that has a checkpoint, start it otherwise
resume_flag() { if [ -f "$1/config.json" ]; then echo --resume; fi; }

motok-robot train tokenizer --data "$PREPARED" --out "$WORK/tokenizer" $(resume_flag "$WORK/tokenizer")
motok-robot train planner --data "$PREPARED" --tokenizer "$WORK/tokenizer" --kind masked \
  --out "$WORK/planner_masked" $(resume_flag "$WORK/planner_masked")
motok-robot train planner --data "$PREPARED" --tokenizer "$WORK/tokenizer" --kind ar \
  --out "$WORK/planner_ar" $(resume_flag "$WORK/planner_ar")
motok-robot train evaluator --data "$PREPARED" --out "$WORK/evaluator" $(resume_flag "$WORK/evaluator")

# ship: weights, configs and training curves only (no optimiser state, no caches)
for name in tokenizer planner_masked planner_ar evaluator; do
  mkdir -p "models/$name"
  for f in config.json model.safetensors metrics.csv training.json; do
    if [ -f "$WORK/$name/$f" ]; then cp "$WORK/$name/$f" "models/$name/$f"; fi
  done
done
echo "models written to models/; check them with: python -m pytest -q tests/test_planner_behaviour.py"
