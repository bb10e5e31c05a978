"""What the env's cameras show: image observations (``ImageObservation``, the env's
``image_obs`` argument) and ``render()`` (``RenderCamera``, its ``render_camera`` argument).
The cameras are :data:`sms3d_env.world.CAMERAS`."""

from __future__ import annotations

from dataclasses import dataclass

from sms3d_env.records import check_choice, image_size
from sms3d_env.world import CAMERAS


@dataclass(frozen=True)
class ImageObservation:
    """RGB-D entries in the observation (``rgb``: H × W × 3 uint8, ``depth``: H × W × 1 float32
    metres).

    Attributes:
        size: (height, width) in pixels.
        camera: one of ``world.CAMERAS``; ``"overhead"`` (default) is the perception camera
            (``"pick"`` is aimed with the true pose at each reset: a privileged view).
    """

    size: tuple[int, int] = (64, 64)
    camera: str = "overhead"

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", image_size("ImageObservation.size", self.size))
        check_choice("ImageObservation.camera", self.camera, CAMERAS)


@dataclass(frozen=True)
class RenderCamera:
    """What ``render()`` shows.

    Attributes:
        name: one of ``world.CAMERAS``; None (default): ``"pick"``, placed at each reset beyond
            the target as seen from the robot's mount, looking at its cap top (the tool and the
            target in view with either robot).
        size: ``render()``'s (height, width) in pixels (``"rgb_array"``, ``"depth_array"``).
    """

    name: str | None = None
    size: tuple[int, int] = (480, 640)

    def __post_init__(self) -> None:
        if self.name is not None:
            check_choice("RenderCamera.name", self.name, CAMERAS)
        object.__setattr__(self, "size", image_size("RenderCamera.size", self.size))
