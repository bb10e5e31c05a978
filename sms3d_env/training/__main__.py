"""``python -m sms3d_env.training {train-policy,eval-policy,learning-curve} ...``."""

from sms3d_env.training.cli import main

raise SystemExit(main())
