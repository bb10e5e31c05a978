#!/usr/bin/env bash
# Reproduce perception/weights/posenet_default.pt, the shipped Point Transformer (the paper's
# stage 2, kept as the baseline), from nothing: eight training steps, each continuing from the
# best network of the step before. Training took about 5.3 hours on 1-2 CPU threads.
#
#   bash perception/weights/reproduce_posenet.sh            # from the repository root
#
# Steps 6-8 cut each mushroom's points with the shipped segmenter's masks out of the segmenter's
# training data (`sms3d train-segmenter segmenter` generates it into runs/seg, the default $DATA).
# Steps 1, 6, 7 and 8 ran under a wall-clock limit (--time-limit-min) and step 2 was stopped by
# hand; here each runs the number of epochs it then ran (its plateau schedule does not depend on
# the total), and step 2 keeps the epoch with the lowest validation stem-axis error, the rule by
# which the shipped file was chosen (train.select_by: axis). Bit-for-bit equality with the
# shipped file has not been checked.
set -euo pipefail
DATA=${DATA:-runs/seg}
CACHE=${CACHE:-runs/pose_cache}
OUT=${OUT:-runs/posenet_recipe}
# The recipe (perception/baselines/point_transformer/recipe.yml) holds step 8's settings; the
# earlier steps replace some with --set (none of them took an occluder's bite out of the clouds;
# steps 3-8 rendered procedural shapes).
NET=(--cache "$CACHE" --quiet)
NO_BITE=train.augment.occlusion_prob=0
SHAPES=data.procedural_models=200

# 1. Synthetic single-mushroom views of the library's models 0-5 of each species.
sms3d train-pose --out "$OUT/1" "${NET[@]}" --epochs 44 --seed 0 --threads 1 \
  --set train.lr=1e-3 train.plateau_patience=3 train.loss=geodesic+axis train.select_by=loss "$NO_BITE" data.num_val=400
# 2. Rendered scenes of 25 mushrooms, with 2,000 of those views mixed in.
sms3d generate --out runs/pose_scenes_train --num-scenes 150 --num-mushrooms 25 --workers 1 --seed 100 --split-ratios 0.9,0.1,0
sms3d train-pose --out "$OUT/2" "${NET[@]}" --init "$OUT/1/best.pt" --scenes runs/pose_scenes_train \
  --epochs 23 --seed 0 --threads 1 --set train.lr=3e-4 train.loss=geodesic+axis "$NO_BITE" data.add_synthetic=2000
# 3. Views of 400 fresh procedural shapes instead of the library's 12.
sms3d train-pose --out "$OUT/3" "${NET[@]}" --init "$OUT/2/best.pt" --scenes runs/pose_scenes_train \
  --epochs 56 --seed 0 --threads 2 \
  --set train.lr=3e-4 train.plateau_patience=3 train.loss=geodesic+axis "$NO_BITE" data.add_synthetic=12000 "$SHAPES"
# 4. The yaw-invariant stem-axis loss, on 400 other shapes.
sms3d train-pose --out "$OUT/4" "${NET[@]}" --init "$OUT/3/best.pt" --scenes runs/pose_scenes_train \
  --epochs 57 --seed 1 --threads 2 --set train.plateau_patience=3 "$NO_BITE" data.add_synthetic=12000 "$SHAPES"
# 5. 2.7 times as many rendered scenes.
sms3d generate --out runs/pose_scenes_train5 --num-scenes 400 --num-mushrooms 25 --workers 2 --seed 102 --split-ratios 0.95,0.05,0
sms3d train-pose --out "$OUT/5" "${NET[@]}" --init "$OUT/4/best.pt" --scenes runs/pose_scenes_train5 \
  --epochs 64 --seed 2 --threads 2 --set train.plateau_patience=3 "$NO_BITE" data.add_synthetic=12000 "$SHAPES"
# 6. For the sensor: clouds cut by the shipped segmenter's masks from clean and camera-model beds.
sms3d train-pose --out "$OUT/6" "${NET[@]}" --init "$OUT/5/best.pt" \
  --scenes "$DATA/clean25" "$DATA/clean40" "$DATA/real25" "$DATA/real40" --masks shipped \
  --epochs 11 --seed 3 --threads 2 --set train.plateau_patience=3 "$NO_BITE" data.add_synthetic=6000 "$SHAPES"
# 7. Annealed on the 40-mushroom beds (the rate halved after every epoch without a new best).
sms3d train-pose --out "$OUT/7" "${NET[@]}" --init "$OUT/6/best.pt" \
  --scenes "$DATA/clean40" "$DATA/real40" --masks shipped \
  --epochs 13 --seed 4 --threads 1 --set train.lr=5e-5 train.plateau_patience=1 "$NO_BITE" data.add_synthetic=2000 "$SHAPES"
# 8. A neighbour's bite taken out of half of the training clouds (occlusion): the recipe as it is.
sms3d train-pose --out "$OUT/8" "${NET[@]}" --init "$OUT/7/best.pt" \
  --scenes "$DATA/clean40" "$DATA/real40" --masks shipped \
  --epochs 31 --seed 8 --threads 2 --set data.add_synthetic=2000 "$SHAPES"

cp "$OUT/8/best.pt" perception/weights/posenet_default.pt
