#!/usr/bin/env bash
# Reproduce perception/weights/axis_cnn/axis_cnn.pt from nothing: 37 generated datasets (the
# first four are the shipped segmenter's training data), then eleven training steps, each
# continuing from the best network of the step before. Training took 298 minutes on 2 CPU
# threads; a dataset of 160 beds takes 65-80 s to generate with one worker and 45-68 s to cut
# into crops (cached in $CACHE).
#
#   bash perception/weights/axis_cnn/reproduce.sh            # from the repository root
#
# DATA, CACHE and OUT move the datasets, the crop cache and the training runs.
set -euo pipefail
DATA=${DATA:-runs/seg}
CACHE=${CACHE:-runs/axis_cache}
OUT=${OUT:-runs/axis_cnn_recipe}

generate() {  # name, beds, mushrooms per bed, seed, [--realism]
  sms3d generate --out "$DATA/$1" --num-scenes "$2" --num-mushrooms "$3" --seed "$4" \
    --split-ratios 0.95,0.05,0 --workers 1 "${@:5}"
}
paths() { for name in "$@"; do printf '%s\n' "$DATA/$name"; done; }
train() {  # step, then train-axis-cnn's options; the datasets come from the array SETS
  local step=$1; shift
  sms3d train-axis-cnn --out "$OUT/$step" --scenes $(paths "${SETS[@]}") --cache "$CACHE" --threads 2 "$@"
}

# Data: clean and camera-model (--realism) beds; the seeds avoid the held-out 9100 / 9200 and
# the fresh evaluation beds' 20100-20600.
generate clean25 240 25 7100;   generate real25 240 25 7300 --realism
generate clean40 160 40 7200;   generate real40 160 40 7400 --realism
generate clean40b 160 40 7600;  generate real40b 160 40 7800 --realism
generate clean40c 160 40 8000;  generate real40c 160 40 8200 --realism
generate clean40d 160 40 8400;  generate real40d 160 40 8600 --realism
generate clean40e 160 40 8800;  generate real40e 160 40 9400 --realism
generate clean40f 160 40 9600;  generate real40f 160 40 9800 --realism
generate clean40g 160 40 10000; generate real40g 160 40 10200 --realism
generate clean40h 160 40 10400; generate real40h 160 40 10600 --realism
generate clean40i 160 40 10800; generate real40i 160 40 11000 --realism
seed=11400
for s in j k l m n o p q r s t u v w x y z; do  # real40j..z: seeds 11400, 11800, ..., 17800
  generate "real40$s" 160 40 "$seed" --realism
  seed=$((seed + 400))
done

# 1. From the upright prior, the first six sets, on 1 - cos.
SETS=(clean25 real25 clean40 real40 clean40b real40b)
train 01 --epochs 40 --loss cosine --seed 0
# 2. Two more sets, a second warm-up and cosine decay at half the peak rate.
SETS+=(clean40c real40c)
train 02 --init "$OUT/01/best.pt" --epochs 25 --lr 1e-3 --loss cosine --seed 1
# 3. Twenty sets, trained on the angle itself (the mean error's own measure).
SETS=(clean25 real25); for s in "" b c d e f g h i; do SETS+=("clean40$s" "real40$s"); done
train 03 --init "$OUT/02/best.pt" --epochs 30 --lr 1e-3 --loss angle --seed 2
# 4. Weighted towards the camera model: the first sixteen sets and eight more --realism ones.
SETS=(clean25 real25); for s in "" b c d e f g; do SETS+=("clean40$s" "real40$s"); done
for s in h i j k l m n o; do SETS+=("real40$s"); done
train 04 --init "$OUT/03/best.pt" --epochs 26 --lr 7e-4 --loss angle --seed 7
# 5-7. The sixteen --realism sets alone, at falling rates.
SETS=(real25); for s in "" b c d e f g h i j k l m n o; do SETS+=("real40$s"); done
train 05 --init "$OUT/04/best.pt" --epochs 6 --lr 2e-4 --loss angle --seed 8
train 06 --init "$OUT/05/best.pt" --epochs 6 --lr 1e-4 --loss angle --seed 9
train 07 --init "$OUT/06/best.pt" --epochs 6 --lr 5e-5 --loss angle --seed 10
# 8-9. Widened to 48 channels / 192 hidden units (the same function), all 27 --realism sets.
for s in p q r s t u v w x y z; do SETS+=("real40$s"); done
train 08 --init "$OUT/07/best.pt" --width 48 --hidden 192 --epochs 8 --lr 3e-4 --loss angle --seed 11
train 09 --init "$OUT/08/best.pt" --epochs 6 --lr 1e-4 --loss angle --seed 12
# 10. Widened again to 64 channels / 256 hidden units.
train 10 --init "$OUT/09/best.pt" --width 64 --hidden 256 --epochs 5 --lr 2e-4 --loss angle --seed 13
# 11. Both cameras again, at a quarter of the rate (the set order fixes the batches).
SETS=(real25 clean25 real40); for s in b c d e f g h i j k l m n o p q r s t u v w x y z; do SETS+=("real40$s"); done
for s in "" b c d e f g; do SETS+=("clean40$s"); done
train 11 --init "$OUT/10/best.pt" --epochs 2 --lr 5e-5 --loss angle --seed 14

cp "$OUT/11/best.pt" perception/weights/axis_cnn/axis_cnn.pt
