"""Stage 1, detection: instance masks of mushrooms (the ``Detector`` protocol, the oracle, the
shipped RGB-D segmenter), its training data and loop, and the COCO evaluation of any detector.
The paper's Mask R-CNN is a baseline: :mod:`perception.baselines.maskrcnn`."""
