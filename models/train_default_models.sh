#!/usr/bin/env bash
# Re-trains the default models shipped in models/ (see models/MODEL_CARD.md for the data,
# licences, times and metrics of the shipped run). CPU is enough: on 2 cores the whole
# script takes about two and a half hours (the AR planner's base run, trained on a GPU for
# the shipped weights, takes 24 min of it and gives a planner like the GPU runs; its
# fine-tune 11 min). Every training step
# is resumable: run the script again after a kill and each stage continues from its last
# checkpoint (--resume).
#
#   bash models/train_default_models.sh [DATASETS_DIR] [WORK_DIR]
#
# DATASETS_DIR holds the archives described in ../shared/datasets/README.md (default
# ../shared/datasets); WORK_DIR receives the prepared data and the runs (default runs/).
# The acRNN archive is prepared separately and kept out of training: it is the "never seen"
# dataset of the tokenizer's reconstruction report.
#
# DEVICE=cuda trains on a GPU (on one H200: tokenizer 3 min, each planner under 5 min while
# four planner runs shared the GPU, evaluator 1 min).
# SPLIT_BY=clip prepares a HumanML3D-style split that holds out single clips instead of whole
# Bandai content/style groups (docs/data.md); the shipped models use the default, group.
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
    --split-by "${SPLIT_BY:-group}" --out "$PREPARED"
fi
SPLIT_HAVE=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1])).get("split_by", "group"))' \
  "$PREPARED/summary.json")
if [ "$SPLIT_HAVE" != "${SPLIT_BY:-group}" ]; then
  echo "error: $PREPARED is split by $SPLIT_HAVE, not ${SPLIT_BY:-group}; use another WORK_DIR" >&2
  exit 2
fi
if [ ! -f "$UNSEEN/index.jsonl" ] && [ -f "$DATA/acrnn-bvh.tar.xz" ]; then
  motok-robot data prepare --source acrnn="$DATA/acrnn-bvh.tar.xz" --out "$UNSEEN"
fi

# resume a run that has a checkpoint, start it otherwise
resume_flag() { if [ -f "$1/config.json" ]; then echo --resume; fi; }

DEV=(--device "${DEVICE:-cpu}")
# fine-tune $WORK/planner_KIND into $WORK/planner_KIND_finetune with models/planner_KIND_finetune.json
# (or resume that fine-tune)
finetune_planner() {
  local from=(--init-from "$WORK/planner_$1" --config "models/planner_$1_finetune.json")
  if [ -f "$WORK/planner_$1_finetune/config.json" ]; then from=(--resume); fi
  motok-robot train planner --data "$PREPARED" --tokenizer "$WORK/tokenizer" --kind "$1" \
    --out "$WORK/planner_$1_finetune" "${from[@]}" "${DEV[@]}"
}
motok-robot train tokenizer --data "$PREPARED" --out "$WORK/tokenizer" "${DEV[@]}" $(resume_flag "$WORK/tokenizer")
# Optional second tokenizer stage (TOKENIZER_STAGE2=1; not part of the shipped models, see the
# model card): the decoder side trained further, encoder + codebook frozen, so the tokens and the
# planners below stay the same. 3,031 steps of 256 windows took 4 minutes on one H200
# (DEVICE=cuda); on 2 CPU cores it would take hours.
TOKENIZER_RUN=tokenizer
if [ "${TOKENIZER_STAGE2:-0}" = 1 ]; then
  TOKENIZER_RUN=tokenizer_decoder
  if [ -f "$WORK/tokenizer_decoder/config.json" ]; then
    motok-robot train tokenizer --data "$PREPARED" --out "$WORK/tokenizer_decoder" --resume "${DEV[@]}"
  else
    motok-robot train tokenizer --data "$PREPARED" --out "$WORK/tokenizer_decoder" --init-from "$WORK/tokenizer" \
      --freeze-tokens --config models/tokenizer_finetune.json "${DEV[@]}"
  fi
fi
# The masked planner is trained with the config defaults, then fine-tuned for 1,500 steps
# (models/planner_masked_finetune.json: balanced sampling, balance_groups 0.5, so rare actions
# such as the 28 bows are drawn more often; the bow group's share of the balanced draws fixed
# at 5 % (action_share); the end embedding switched on, starting at zero; learning rate 1e-4;
# training seed 1), which is the shipped one. The AR planner's recipe is
# models/planner_ar_train.json: 6 layers, four token grids per clip and balance_groups 0.5 from
# the start, the end embedding with end_horizon 8 (the count of tokens still to draw, shown
# only in the last 8 tokens), training seed 1 (one of eight GPU runs; the training seed alone
# moves its bows by several of 48 seeds), then fine-tuned for 1,500 steps
# (models/planner_ar_finetune.json: the same token grids and balancing, the bow group's share
# 10 %, five bows whose tokens decode shallow left out with their mirrors (exclude_clips),
# learning rate 1e-4, training seed 1), which is the shipped one. See models/MODEL_CARD.md,
# "The masked planner fine-tuned with balanced sampling and the end embedding", "The masked
# planner's fine-tune with a bow share" and "The AR planner fine-tuned on curated bows".
motok-robot train planner --data "$PREPARED" --tokenizer "$WORK/tokenizer" --kind masked \
  --out "$WORK/planner_masked" "${DEV[@]}" $(resume_flag "$WORK/planner_masked")
finetune_planner masked
motok-robot train planner --data "$PREPARED" --tokenizer "$WORK/tokenizer" --kind ar \
  --config models/planner_ar_train.json --out "$WORK/planner_ar" "${DEV[@]}" $(resume_flag "$WORK/planner_ar")
finetune_planner ar
motok-robot train evaluator --data "$PREPARED" --out "$WORK/evaluator" "${DEV[@]}" $(resume_flag "$WORK/evaluator")

# ship: weights, configs and training curves only (no optimiser state, no caches)
for name in tokenizer planner_masked planner_ar evaluator; do
  run=$name
  if [ "$name" = tokenizer ]; then run=$TOKENIZER_RUN; fi
  case $name in planner_*) run=${name}_finetune ;; esac   # both planners ship their fine-tunes
  mkdir -p "models/$name"
  for f in config.json model.safetensors metrics.csv training.json; do
    if [ -f "$WORK/$run/$f" ]; then cp "$WORK/$run/$f" "models/$name/$f"; fi
  done
done
echo "models written to models/; check them with: python -m pytest -q tests/test_planner_behaviour.py"
