"""The SMS3D paper's perception models, kept as baselines to measure the shipped pipeline against.

- :mod:`perception.baselines.maskrcnn`: Mask R-CNN (torchvision) for stage 1, instance masks
  from RGB. Needs the ``baselines`` extra (``pip install -e ".[baselines]"``).
- :mod:`perception.baselines.point_transformer`: the Point Transformer with a 6D rotation head
  for stage 2, a rotation from each mask's back-projected points; with its data, training,
  recipe (``recipe.yml``, read by ``sms3d train-pose``), evaluation and ablations.

The shipped pipeline (``perception.pipeline.PosePipeline.shipped``) uses neither: the RGB-D
segmenter (``perception.detection.rgbd_segmenter``) and the axis CNN
(``perception.pose.axis_cnn``). Both baselines plug into it: ``load_detector(PATH)`` reads a
Mask R-CNN checkpoint, and ``PosePipeline(PoseEstimator.from_pretrained())`` runs the point
network.
"""
