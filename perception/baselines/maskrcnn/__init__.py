"""Mask R-CNN for stage 1 (the SMS3D authors' detector), a baseline: the network and its
checkpoints (``model``), its settings without torch (``config``) and its training loop
(``train``, ``sms3d train-detector``). It needs torchvision: ``pip install -e ".[baselines]"``."""
