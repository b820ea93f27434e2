"""Settings of controlled decoding (defaults in one place)."""

from __future__ import annotations

from dataclasses import dataclass

MECHANISMS = ("motok", "gmd", "inpaint", "none")


@dataclass
class ControlConfig:
    """How constraints are enforced while the MoTok decoder denoises.

    ``mechanisms`` is any combination of ``motok`` (gradient refinement of the clean
    estimate at every step), ``gmd`` (imputation of the root trajectory + dense guidance
    through the denoiser) and ``inpaint`` (MDM: overwrite the known part of the clean
    estimate at every step); ``none`` decodes without control.
    """

    #: default: GMD makes the root path exact, the refinement then meets the other constraints
    #: and the physics terms (measured in docs/control.md)
    mechanisms: tuple[str, ...] = ("gmd", "motok")
    #: MoTok refinement: Adam learning rate in normalised feature units, and inner iterations
    refine_lr: float = 0.1
    refine_iters: int = 4
    #: iterations at the final (clean) step, where the constraint is enforced precisely
    refine_final_iters: int = 300
    #: GMD dense guidance scale s (mu_t -= (1 - M) s Sigma_t grad)
    gmd_scale: float = 50.0
    #: GMD: impute the root trajectory in x0 at every step
    gmd_impute: bool = True
    obstacle_weight: float = 10.0
    foot_weight: float = 1.0
    #: keeps bone lengths (joint positions from features are not tied by bones)
    bone_weight: float = 10.0
    #: make prefix / suffix frames exact after sampling (in-betweening)
    exact_seams: bool = True
    #: free frames next to a seam whose pose is cross-faded from the kept frames (0 = none)
    seam_blend_frames: int = 10

    def __post_init__(self) -> None:
        from motok_robot.errors import InputError

        if isinstance(self.mechanisms, str):
            self.mechanisms = tuple(m.strip() for m in self.mechanisms.split(",") if m.strip())
        unknown = [m for m in self.mechanisms if m not in MECHANISMS]
        if unknown:
            raise InputError(f"--guidance: unknown mechanism(s) {unknown} (choose from {', '.join(MECHANISMS)})")
        if "none" in self.mechanisms and len(self.mechanisms) > 1:
            raise InputError("--guidance: 'none' cannot be combined with other mechanisms")
