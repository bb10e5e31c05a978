"""Stage 1, detection: instance masks of mushrooms (the ``Detector`` protocol, the oracle, the
shipped RGB-D segmenter, Mask R-CNN), their training data, training loops and evaluation."""
