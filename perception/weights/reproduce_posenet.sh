#!/usr/bin/env bash
# Reproduce perception/weights/posenet_default.pt, the shipped Point Transformer (the paper's
# stage 2, kept as the baseline), from nothing: eight training steps, each continuing from the
# best network of the step before. Training took about 5.3 hours on 1-2 CPU threads.
#
#   bash perception/weights/reproduce_posenet.sh            # from the repository root
#
# Steps 6-8 cut each mushroom's points with the shipped segmenter's masks out of the segmenter's
# training data (perception/weights/segmenter/reproduce.sh generates it into $DATA).
# Steps 1, 6, 7 and 8 ran under a wall-clock limit (--time-limit-min) and step 2 was stopped by
# hand; here each runs the number of epochs it then ran (its plateau schedule does not depend on
# the total), and step 2 keeps the epoch with the lowest validation stem-axis error, the rule by
# which the shipped file was chosen (--select-by axis). Bit-for-bit equality with the shipped file
# has not been checked.
set -euo pipefail
DATA=${DATA:-runs/seg}
CACHE=${CACHE:-runs/pose_cache}
OUT=${OUT:-runs/posenet_recipe}
NET=(--backbone point_transformer --head 6d --num-points 512 --cache "$CACHE" --quiet)

# 1. Synthetic single-mushroom views of the library's models 0-5 of each species.
sms3d train-pose --out "$OUT/1" "${NET[@]}" --epochs 44 --lr 1e-3 --patience 3 --loss geodesic+axis \
  --num-train 4000 --num-val 400 --seed 0 --threads 1
# 2. Rendered scenes of 25 mushrooms, with 2,000 of those views mixed in.
sms3d generate --out runs/pose_scenes_train --num-scenes 150 --num-mushrooms 25 --workers 1 --seed 100 --split-ratios 0.9,0.1,0
sms3d train-pose --out "$OUT/2" "${NET[@]}" --init "$OUT/1/best.pt" --scenes runs/pose_scenes_train \
  --add-synthetic 2000 --epochs 23 --lr 3e-4 --patience 2 --loss geodesic+axis --select-by axis --seed 0 --threads 1
# 3. Views of 400 fresh procedural shapes instead of the library's 12.
sms3d train-pose --out "$OUT/3" "${NET[@]}" --init "$OUT/2/best.pt" --scenes runs/pose_scenes_train \
  --add-synthetic 12000 --procedural-models 200 --epochs 56 --lr 3e-4 --patience 3 --loss geodesic+axis \
  --select-by axis --seed 0 --threads 2
# 4. The yaw-invariant stem-axis loss, on 400 other shapes.
sms3d train-pose --out "$OUT/4" "${NET[@]}" --init "$OUT/3/best.pt" --scenes runs/pose_scenes_train \
  --add-synthetic 12000 --procedural-models 200 --epochs 57 --lr 1e-4 --patience 3 --loss axis \
  --select-by axis --seed 1 --threads 2
# 5. 2.7 times as many rendered scenes.
sms3d generate --out runs/pose_scenes_train5 --num-scenes 400 --num-mushrooms 25 --workers 2 --seed 102 --split-ratios 0.95,0.05,0
sms3d train-pose --out "$OUT/5" "${NET[@]}" --init "$OUT/4/best.pt" --scenes runs/pose_scenes_train5 \
  --add-synthetic 12000 --procedural-models 200 --epochs 64 --lr 1e-4 --patience 3 --loss axis \
  --select-by axis --seed 2 --threads 2
# 6. For the sensor: clouds cut by the shipped segmenter's masks from clean and camera-model beds.
sms3d train-pose --out "$OUT/6" "${NET[@]}" --init "$OUT/5/best.pt" \
  --scenes "$DATA/clean25" "$DATA/clean40" "$DATA/real25" "$DATA/real40" --masks shipped \
  --add-synthetic 6000 --procedural-models 200 --epochs 11 --lr 1e-4 --patience 3 --loss axis \
  --select-by axis --seed 3 --threads 2
# 7. Annealed on the 40-mushroom beds (the rate halved after every epoch without a new best).
sms3d train-pose --out "$OUT/7" "${NET[@]}" --init "$OUT/6/best.pt" \
  --scenes "$DATA/clean40" "$DATA/real40" --masks shipped --add-synthetic 2000 --procedural-models 200 \
  --epochs 13 --lr 5e-5 --patience 1 --loss axis --select-by axis --seed 4 --threads 1
# 8. A neighbour's bite taken out of half of the training clouds (occlusion).
sms3d train-pose --out "$OUT/8" "${NET[@]}" --init "$OUT/7/best.pt" \
  --scenes "$DATA/clean40" "$DATA/real40" --masks shipped --add-synthetic 2000 --procedural-models 200 \
  --epochs 31 --lr 1e-4 --patience 2 --loss axis --select-by axis --seed 8 --threads 2 --occlusion-prob 0.5

cp "$OUT/8/best.pt" perception/weights/posenet_default.pt
