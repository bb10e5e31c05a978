"""Dataset options: splits, rendering and seeded realism (all realism off by default)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from generator.config import is_number
from generator.errors import ConfigError

# RealSense-like stereo baselines in metres (docs/physics.md, cameras).
STEREO_BASELINE_M = {"d405": 0.018, "d435": 0.050}


@dataclass(frozen=True)
class RealismOptions:
    """Seeded sensor and appearance randomisation. Every switch is off by default."""

    depth_noise: bool = False  # sigma_z = z^2 * subpixel / (f_px * baseline)
    depth_noise_subpixel: float = 0.08  # px, Intel's typical value (0.032 at best)
    edge_holes: bool = False  # invalid (0) depth at depth discontinuities, like stereo sensors
    edge_threshold: float = 0.008  # m, neighbour depth step that counts as an edge
    edge_hole_probability: float = 0.6  # chance an edge pixel (dilated by 1 px) becomes a hole
    lighting: bool = False  # light intensity, direction and ambient jitter
    soil: bool = False  # soil tint and texture repeat jitter
    camera_jitter: bool = False  # camera height and tilt jitter
    camera_height_jitter: float = 0.03  # m, uniform +-
    camera_tilt_jitter_deg: float = 5.0  # deg, tilt away from straight down about a random axis
    # Stereo camera model (docs/physics.md, cameras). Disparity d = f_px * B / z, in pixels.
    correlated_noise: bool = False  # disparity noise of std depth_noise_subpixel, correlated over the
    #   matching window; replaces the white depth_noise draw when both are on (noise is applied once)
    matching_window_px: int = 7  # side of the box the N(0, 1) field is averaged over (1: white)
    disparity_quantisation: bool = False  # disparity rounded to multiples of disparity_step_px
    disparity_step_px: float = 1.0 / 32.0  # the D4 processor's 1/32-pixel subpixel resolution
    flying_pixels: bool = False  # mixed depths between the near and far side of depth edges
    flying_pixel_probability: float = 0.5  # chance an edge pixel (step > edge_threshold) is mixed
    stereo_shadows: bool = False  # invalid where the right imager cannot see the left imager's point
    stereo_shadows_left_band: bool = True  # with stereo_shadows, also the band at the image's left
    #   edge whose points fall outside the right image (width f B / z)
    rgb_noise: bool = False  # Poisson-Gaussian sensor noise, variance rgb_noise_gain * I + read^2 (DN)
    rgb_noise_gain: float = 0.1  # DN of variance per DN of signal (shot noise)
    rgb_read_noise_dn: float = 2.0  # DN, std of the signal-independent read noise
    rgb_blur: bool = False  # Gaussian blur (defocus, motion), sigma ~ U(0, blur_sigma_max_px)
    blur_sigma_max_px: float = 1.0
    exposure: bool = False  # exposure gain 2**U(-exposure_stops, +exposure_stops), before the noise
    exposure_stops: float = 0.5

    def __post_init__(self) -> None:
        for name in ("depth_noise_subpixel", "edge_threshold", "camera_height_jitter", "camera_tilt_jitter_deg",
                     "rgb_noise_gain", "rgb_read_noise_dn", "blur_sigma_max_px", "exposure_stops"):
            v = getattr(self, name)
            if not is_number(v) or not math.isfinite(v) or v < 0:
                raise ConfigError(f"realism.{name}", f"must be a finite number >= 0, got {v!r}")
        for name in ("edge_hole_probability", "flying_pixel_probability"):
            p = getattr(self, name)
            if not is_number(p) or not 0 <= p <= 1:
                raise ConfigError(f"realism.{name}", f"must be in [0, 1], got {p!r}")
        if self.camera_tilt_jitter_deg > 30:
            raise ConfigError("realism.camera_tilt_jitter_deg", "must be <= 30")
        w = self.matching_window_px
        if not isinstance(w, int) or isinstance(w, bool) or not 1 <= w <= 63:
            raise ConfigError("realism.matching_window_px", f"must be an integer in [1, 63], got {w!r}")
        step = self.disparity_step_px
        if not is_number(step) or not math.isfinite(step) or not 0 < step <= 1:
            raise ConfigError("realism.disparity_step_px", f"must be a finite number in (0, 1], got {step!r}")
        for name, limit in (("blur_sigma_max_px", 10.0), ("exposure_stops", 4.0), ("rgb_read_noise_dn", 64.0),
                            ("rgb_noise_gain", 16.0)):
            if getattr(self, name) > limit:
                raise ConfigError(f"realism.{name}", f"must be <= {limit:g}")

    @classmethod
    def all_on(cls) -> RealismOptions:
        """Every effect on with its default parameters (``sms3d generate --realism``)."""
        return cls(**{name: True for name in REALISM_SWITCHES})

    @property
    def depth_any(self) -> bool:
        """Whether ``apply_depth_realism`` changes the depth image."""
        return (self.depth_noise or self.edge_holes or self.correlated_noise or self.disparity_quantisation
                or self.flying_pixels or self.stereo_shadows)

    @property
    def rgb_any(self) -> bool:
        """Whether ``apply_rgb_realism`` changes the RGB image."""
        return self.rgb_noise or self.rgb_blur or self.exposure

    @property
    def any(self) -> bool:
        return self.depth_any or self.rgb_any or self.lighting or self.soil or self.camera_jitter

    def to_dict(self) -> dict[str, Any]:
        """The fields, less the camera-model ones (``CAMERA_MODEL_FIELDS``) while none of its
        switches is on: datasets made with only the older options record the same settings as
        before (the same ``scene.json`` bytes, and old datasets still resume)."""
        d = dataclasses.asdict(self)
        if not any(d[name] for name in CAMERA_MODEL_SWITCHES):
            for name in CAMERA_MODEL_FIELDS:
                del d[name]
        return d


# The switches of the options first offered (lighting, soil and camera jitter, white depth noise,
# edge holes), then those of the stereo camera model and RGB sensor effects added after them.
ORIGINAL_SWITCHES = ("depth_noise", "edge_holes", "lighting", "soil", "camera_jitter")
CAMERA_MODEL_SWITCHES = ("correlated_noise", "disparity_quantisation", "flying_pixels", "stereo_shadows",
                         "rgb_noise", "rgb_blur", "exposure")
REALISM_SWITCHES = (*ORIGINAL_SWITCHES, *CAMERA_MODEL_SWITCHES)
CAMERA_MODEL_FIELDS = (*CAMERA_MODEL_SWITCHES, "matching_window_px", "disparity_step_px",
                       "flying_pixel_probability", "stereo_shadows_left_band", "rgb_noise_gain",
                       "rgb_read_noise_dn", "blur_sigma_max_px", "exposure_stops")


@dataclass(frozen=True)
class DatasetOptions:
    """How scenes become dataset files (the scene itself comes from ``SceneConfig``)."""

    split_ratios: tuple[float, float, float] = (0.8, 0.1, 0.1)  # train, val, test
    shadows: bool = False
    realism: RealismOptions = field(default_factory=RealismOptions)

    def __post_init__(self) -> None:
        ratios = tuple(float(r) for r in self.split_ratios)
        object.__setattr__(self, "split_ratios", ratios)
        if len(ratios) != 3 or any(not math.isfinite(r) or r < 0 for r in ratios) or sum(ratios) <= 0:
            raise ConfigError("split_ratios", f"need three finite ratios >= 0 with a positive sum, got {self.split_ratios!r}")
        if isinstance(self.realism, Mapping):
            object.__setattr__(self, "realism", RealismOptions(**self.realism))

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["realism"] = self.realism.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DatasetOptions:
        try:
            return cls(split_ratios=tuple(data.get("split_ratios", (0.8, 0.1, 0.1))),
                       shadows=bool(data.get("shadows", False)),
                       realism=RealismOptions(**dict(data.get("realism", {}))))
        except TypeError as exc:
            raise ConfigError("dataset", str(exc)) from exc
