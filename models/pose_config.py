"""Configuration of the multimodal pose network (RGB CNN + point net + ECFT + FFB6D heads)."""

from __future__ import annotations

from dataclasses import dataclass

from spacepose.pose_inputs import PoseInputSpec

__all__ = ["PoseNetConfig", "FUSIONS", "ATTENTIONS"]

#: Fusion directions of paper Table 5. "rgb2pt": RGB features flow into the point branch (only the
#: point features are updated); "pt2rgb": point features flow into the RGB branch; "none": no ECFT
#: (the heads still see both branches, concatenated per point).
FUSIONS = ("both", "rgb2pt", "pt2rgb", "none")
#: Attention inside the ECFT (paper Table 6): additive ECAA (linear) or dot-product (quadratic).
ATTENTIONS = ("ecaa", "vanilla")


@dataclass(frozen=True)
class PoseNetConfig:
    """Sizes and variants of :class:`spacepose.models.pose_net.PoseNet`.

    ``crop_size`` is (width, height). Level ``l`` of the point net (N_l = n_points // ratio**l
    points) is fused with the RGB feature map at stride ``4 * 2**l``; the widths tuples hold one
    entry per level.
    """

    crop_size: tuple[int, int] = (128, 128)
    n_points: int = 1024
    k: int = 16
    n_levels: int = 3
    ratio: int = 4
    use_normals: bool = False
    xyz_scale: float = 2.5
    sampling: str = "fps"
    rgb_stem: int = 16
    rgb_widths: tuple[int, ...] = (32, 64, 128)
    rgb_bottleneck: int = 128
    rgb_out: int = 32
    point_stem: int = 16
    point_widths: tuple[int, ...] = (32, 64, 128)
    point_bottleneck: int = 128
    head_width: int = 64
    n_keypoints: int = 8
    n_classes: int = 2
    fusion: str = "both"
    attention: str = "ecaa"
    fuse_decoder: bool = True
    ffn_ratio: float = 2.0
    vanilla_heads: int = 4

    def __post_init__(self) -> None:
        if self.fusion not in FUSIONS:
            raise ValueError(f"fusion must be one of {FUSIONS}, got {self.fusion!r}")
        if self.attention not in ATTENTIONS:
            raise ValueError(f"attention must be one of {ATTENTIONS}, got {self.attention!r}")
        if len(self.rgb_widths) != self.n_levels or len(self.point_widths) != self.n_levels:
            raise ValueError("rgb_widths and point_widths need one entry per level")
        if self.n_keypoints < 1 or self.n_classes < 2:
            raise ValueError("n_keypoints must be >= 1 and n_classes >= 2")
        if self.attention == "vanilla" and any(min(r, p) % self.vanilla_heads for r, p in zip(self.rgb_widths, self.point_widths)):
            raise ValueError("vanilla_heads must divide every ECFT width")
        self.input_spec()  # validates crop / point counts

    @property
    def point_channels(self) -> int:
        return 9 if self.use_normals else 6

    def ecft_dim(self, level: int) -> int:
        """Embedding width d of the ECFT blocks at ``level``."""
        return min(self.rgb_widths[level], self.point_widths[level])

    def input_spec(self, seed: int = 0) -> PoseInputSpec:
        """The numpy-side description of the graph inputs (see :mod:`spacepose.pose_inputs`)."""
        return PoseInputSpec(n_points=self.n_points, k=self.k, n_levels=self.n_levels, ratio=self.ratio,
                             crop_size=self.crop_size, xyz_scale=self.xyz_scale, use_normals=self.use_normals,
                             sampling=self.sampling, seed=seed)

    @classmethod
    def from_dict(cls, data: dict) -> "PoseNetConfig":
        """Inverse of ``dataclasses.asdict`` after a JSON round trip (lists back to tuples)."""
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})

    @classmethod
    def cpu(cls, **overrides) -> "PoseNetConfig":
        """CPU-sized default: 128x128 crop, 1,024 points, 3 levels, ~1 M parameters."""
        return cls(**overrides)

    @classmethod
    def paper(cls, **overrides) -> "PoseNetConfig":
        """FFB6D-sized: 12,800 points, 4 levels of x4, k = 16, xyz+rgb+normals, wide branches."""
        base = dict(crop_size=(256, 256), n_points=12800, n_levels=4, use_normals=True, rgb_stem=32,
                    rgb_widths=(64, 128, 256, 512), rgb_bottleneck=512, rgb_out=64, point_stem=32,
                    point_widths=(64, 128, 256, 512), point_bottleneck=512, head_width=128)
        base.update(overrides)
        return cls(**base)
