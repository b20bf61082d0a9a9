"""Configuration of TSCA-Stereo: one frozen dataclass selects the variant and every width.

The four variants of paper Table 4:

| variant | Triplet Attention in context net | dw-separable 3D encoder + SECA |
|---------|----------------------------------|--------------------------------|
| "igev"  | no                               | no                             |
| "ta"    | yes                              | no                             |
| "seca"  | no                               | yes                            |
| "full"  | yes                              | yes                            |

Scales: the feature net runs at 1/2, 1/4, 1/8, 1/16, 1/32; the cost volume, the regulariser's
finest level and the finest ConvGRU run at 1/4. ``max_disp`` is in full-resolution pixels.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

from spacepose.errors import SpaceposeError

__all__ = ["StereoConfig", "VARIANTS"]

VARIANTS = ("igev", "ta", "seca", "full")


@dataclass(frozen=True)
class StereoConfig:
    """Hyper-parameters of TSCA-Stereo (serialisable with ``dataclasses.asdict``).

    feature_widths: channels of the feature net at 1/2, 1/4, 1/8, 1/16, 1/32 (5 entries).
    match_dim: channels of the 1/4 matching features (cost volumes are built from them).
    context_widths: channels of the context net stem (1/2) then one per GRU level (1/4, 1/8, 1/16).
    hidden_dims: ConvGRU hidden channels per level (1/4, 1/8, 1/16); first n_gru_layers are used.
    reg_widths: 3D regulariser channels at 1/4 (= geometry encoding volume channels), 1/8, 1/16, 1/32.
    seca_depthwise_qk: make SECA's 3x3x3 / 5x5x5 query/key convs depthwise (a CPU-cost knob).
    seca_quarter_res: SECA also in the 1/4-resolution decoder block (paper: yes; the CPU model
        uses the baseline 1x1x1 + 3x3x3 aggregation there, SECA costs ~0.5 s at 1/4 in torch eager).

    The defaults are the CPU model (``cpu()``): 3D widths are multiples of 16 because torch's
    CPU Conv3d is 3-5x slower per MAC with fewer input channels; the finest GRU is kept narrow
    (32) since it dominates the per-iteration cost.
    """

    variant: str = "full"
    feature_widths: tuple[int, ...] = (16, 24, 32, 48, 64)
    match_dim: int = 64
    context_widths: tuple[int, ...] = (32, 48, 64, 64)
    hidden_dims: tuple[int, ...] = (32, 48, 64)
    n_gru_layers: int = 2
    motion_dim: int = 32
    groups: int = 16
    reg_widths: tuple[int, ...] = (16, 16, 32, 32)
    seca_depthwise_qk: bool = True
    seca_quarter_res: bool = False
    corr_levels: int = 2
    corr_radius: int = 4
    max_disp: int = 96
    iters: int = 4
    train_iters: int = 4

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise SpaceposeError(f"unknown stereo variant {self.variant!r}; valid: {VARIANTS}")
        for name in ("feature_widths", "context_widths", "hidden_dims", "reg_widths"):
            object.__setattr__(self, name, tuple(int(v) for v in getattr(self, name)))
        if len(self.feature_widths) != 5:
            raise SpaceposeError("feature_widths needs 5 entries (1/2 .. 1/32)")
        if len(self.reg_widths) != 4:
            raise SpaceposeError("reg_widths needs 4 entries (1/4 .. 1/32)")
        if not 1 <= self.n_gru_layers <= 3:
            raise SpaceposeError("n_gru_layers must be 1, 2 or 3")
        if len(self.hidden_dims) < self.n_gru_layers or len(self.context_widths) < 1 + self.n_gru_layers:
            raise SpaceposeError("hidden_dims / context_widths too short for n_gru_layers")
        if self.match_dim % self.groups:
            raise SpaceposeError("match_dim must be a multiple of groups")
        if self.max_disp <= 0 or self.max_disp % 32:
            raise SpaceposeError("max_disp must be a positive multiple of 32 (D/4 pooled 3 times)")
        if self.corr_levels < 1 or self.corr_radius < 0 or self.iters < 0 or self.train_iters < 1:
            raise SpaceposeError("corr_levels >= 1, corr_radius >= 0, iters >= 0, train_iters >= 1")

    @property
    def use_triplet_attention(self) -> bool:
        return self.variant in ("ta", "full")

    @property
    def use_seca(self) -> bool:
        return self.variant in ("seca", "full")

    @property
    def use_dwsep(self) -> bool:
        """Depthwise-separable 3D convs in the regulariser encoder (part of the improved regulariser)."""
        return self.variant in ("seca", "full")

    @property
    def num_disp(self) -> int:
        """Number of disparity candidates in the 1/4-resolution volumes."""
        return self.max_disp // 4

    @property
    def lookup_channels(self) -> int:
        """Channels of one lookup: levels * (2r+1) * (geometry channels + 1 all-pairs channel)."""
        return self.corr_levels * (2 * self.corr_radius + 1) * (self.reg_widths[0] + 1)

    def replace(self, **changes: Any) -> "StereoConfig":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "StereoConfig":
        """Inverse of ``to_dict`` (lists from JSON become tuples); unknown keys raise."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise SpaceposeError(f"unknown StereoConfig keys: {sorted(unknown)}")
        return cls(**dict(data))

    @classmethod
    def cpu(cls, variant: str = "full") -> "StereoConfig":
        """CPU-sized model for 256x256 inputs, disparities up to 96 px, 4 iterations."""
        return cls(variant=variant)

    @classmethod
    def paper(cls, variant: str = "full") -> "StereoConfig":
        """Paper-sized model: IGEV widths, 3 GRU levels of 128, max_disp 192, 32/22 iterations."""
        return cls(
            variant=variant,
            feature_widths=(32, 48, 64, 192, 160),
            match_dim=96,
            context_widths=(64, 128, 128, 128),
            hidden_dims=(128, 128, 128),
            n_gru_layers=3,
            motion_dim=128,
            groups=8,
            reg_widths=(8, 16, 32, 48),
            seca_depthwise_qk=False,
            seca_quarter_res=True,
            corr_levels=2,
            corr_radius=4,
            max_disp=192,
            iters=32,
            train_iters=22,
        )
