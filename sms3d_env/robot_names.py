"""The names of ``SMS3DPick-v1``'s robots, importable without MuJoCo (command-line parsers and
settings check them before any world is built); ``sms3d_env.robots`` builds them."""

ROBOTS: tuple[str, ...] = ("gantry", "jaco")
