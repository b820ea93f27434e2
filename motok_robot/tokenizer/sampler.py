"""Cosine noise schedule, DDIM sampler and the guidance hook protocol.

Diffusion runs in *model space*: normalised features (``(x - mean) / std``), passed through
the emphasis projection when the tokenizer uses it.  ``x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps``.

Guidance protocol (the control stage's hook into decoding)
---------------------------------------------------------
``decode(..., guidance=g)`` accepts any object with a method ``g.step(state) -> None`` (or a
plain callable ``g(state) -> None``).  It is called once per DDIM step, *after* the denoiser
produced ``state.x0_hat`` and *before* the DDIM update, and may modify ``state.x_t`` and/or
``state.x0_hat`` in place or by assigning new tensors.  The sampler then continues with

    eps_hat = (x_t - sqrt(abar_t) x0_hat) / sqrt(1 - abar_t)
    x_prev  = sqrt(abar_prev) x0_hat + sqrt(1 - abar_prev - sigma^2) eps_hat + sigma * noise

so the same hook works with both the ``x0`` and the ``eps`` parameterisation:

* **imputation / inpainting** (GMD, MDM editing): overwrite parts of ``state.x0_hat`` (in
  model space; go through ``state.to_features`` / ``state.from_features`` to edit raw
  features, e.g. the root trajectory), e.g.
  ``x = state.to_features(state.x0_hat); x[..., 0:4] = target; state.x0_hat = state.from_features(x)``;
* **dense gradient guidance through the denoiser** (GMD): with ``torch.enable_grad()``, take
  ``x = state.x_t.detach().requires_grad_()``, ``x0 = state.denoise(x)`` (differentiable),
  a loss on ``state.to_features(x0)``, its gradient w.r.t. ``x``; then set
  ``state.x_t = x - lr * grad`` and ``state.x0_hat = state.denoise(state.x_t).detach()``;
* **x0 refinement** (MoTok's control loss at each step): gradient steps on ``state.x0_hat``.

At the last step ``state.x0_hat`` after the hook is the output.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import torch


def cosine_alpha_bar(diffusion_steps: int, s: float = 0.008, max_beta: float = 0.999) -> torch.Tensor:
    """Cumulative signal level ``abar[t]`` for ``t = 0 .. diffusion_steps - 1`` (float64, decreasing
    from ~1 to ~0) of the cosine schedule (Nichol & Dhariwal), betas clipped at ``max_beta``."""
    steps = torch.arange(diffusion_steps + 1, dtype=torch.float64)
    f = torch.cos((steps / diffusion_steps + s) / (1 + s) * math.pi / 2) ** 2
    betas = (1 - f[1:] / f[:-1]).clamp(max=max_beta)
    return torch.cumprod(1 - betas, dim=0)


def ddim_timesteps(diffusion_steps: int, steps: int) -> list[int]:
    """``steps`` timesteps evenly spread over ``diffusion_steps - 1 .. 0``, descending, unique."""
    if steps < 1:
        from motok_robot.errors import InputError

        raise InputError(f"decode: steps must be >= 1 (got {steps})")
    steps = min(steps, diffusion_steps)
    ts = torch.linspace(diffusion_steps - 1, 0, steps).round().long().tolist()
    out: list[int] = []
    for t in ts:
        if not out or t != out[-1]:
            out.append(int(t))
    return out


@dataclass
class GuidanceState:
    """What a guidance hook sees at one DDIM step (tensors ``[B, T, F]`` in model space)."""

    step: int  #: index of this step, 0 .. steps - 1
    steps: int  #: number of DDIM steps of this decode
    t: int  #: diffusion timestep of x_t (0 .. diffusion_steps - 1)
    t_prev: int  #: timestep the update moves to (-1 at the last step: the clean motion)
    alpha_bar: float  #: abar_t, signal level of x_t
    alpha_bar_prev: float  #: abar of the next state (1.0 at the last step)
    sigma: float  #: noise std of x_t, sqrt(1 - abar_t)
    x_t: torch.Tensor  #: current noisy motion (may be replaced / edited by the hook)
    x0_hat: torch.Tensor  #: denoiser's clean estimate (may be replaced / edited by the hook)
    denoise: Callable[[torch.Tensor], torch.Tensor]  #: differentiable x_t -> x0_hat at this t and condition
    projection: Any  #: the EmphasisProjection, or None when the tokenizer does not use one
    normalise: Callable[[torch.Tensor], torch.Tensor]  #: raw features -> normalised
    denormalise: Callable[[torch.Tensor], torch.Tensor]  #: normalised -> raw features
    to_features: Callable[[torch.Tensor], torch.Tensor]  #: model space -> raw features (differentiable)
    from_features: Callable[[torch.Tensor], torch.Tensor]  #: raw features -> model space (differentiable)
    parameterisation: str  #: "x0" or "eps" (what the denoiser predicts)
    condition: torch.Tensor | None = None  #: per-frame conditioning s [B, T, cond_dim] from the tokens


@runtime_checkable
class Guidance(Protocol):
    """A hook into the sampler: ``step(state)`` may modify ``state.x_t`` / ``state.x0_hat``."""

    def step(self, state: GuidanceState) -> None: ...


def _hook(guidance: Any) -> Callable[[GuidanceState], None] | None:
    if guidance is None:
        return None
    if hasattr(guidance, "step") and callable(guidance.step):
        return guidance.step
    if callable(guidance):
        return guidance
    from motok_robot.errors import InputError

    raise InputError(f"guidance must have a step(state) method or be callable (got {type(guidance).__name__})")


#: in the eps parameterisation x0_hat = (x_t - sqrt(1-abar) eps) / sqrt(abar) explodes at the
#: noisiest steps (abar ~ 0); it is clamped to this many standard deviations of the data
EPS_X0_CLAMP = 20.0


def predict_x0(prediction: torch.Tensor, x_t: torch.Tensor, alpha_bar: float, parameterisation: str) -> torch.Tensor:
    """Convert a denoiser output to the clean-motion estimate (model space)."""
    if parameterisation == "x0":
        return prediction
    x0 = (x_t - math.sqrt(1.0 - alpha_bar) * prediction) / math.sqrt(max(alpha_bar, 1e-12))
    return x0.clamp(-EPS_X0_CLAMP, EPS_X0_CLAMP)


def ddim_sample(
    model_fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    shape: tuple[int, ...],
    alpha_bar: torch.Tensor,
    *,
    steps: int,
    parameterisation: str,
    seed: int = 0,
    eta: float = 0.0,
    device: torch.device | str = "cpu",
    dtype: torch.dtype = torch.float32,
    guidance: Any = None,
    state_extras: dict[str, Any] | None = None,
    noise: torch.Tensor | None = None,
) -> torch.Tensor:
    """DDIM from pure noise to a clean sample ``[*shape]`` (model space).

    ``model_fn(x_t, t)`` returns the denoiser prediction (``t`` an int64 tensor ``[B]``);
    ``alpha_bar`` the schedule; the initial noise (and the DDIM noise when ``eta > 0``) is drawn
    on the CPU from ``torch.Generator().manual_seed(seed)``, so a seed gives the same sample on
    CPU and CUDA up to floating point.  ``noise`` overrides the initial noise.
    ``state_extras`` fills the :class:`GuidanceState` fields the sampler does not know
    (projection, normalise, denormalise, to_features, from_features, condition).
    """
    hook = _hook(guidance)
    generator = torch.Generator().manual_seed(int(seed))
    if noise is None:
        noise = torch.randn(shape, generator=generator, dtype=torch.float32)
    x_t = noise.to(device=device, dtype=dtype)
    timesteps = ddim_timesteps(alpha_bar.shape[0], steps)
    batch = shape[0]
    x0_hat = x_t
    for i, t in enumerate(timesteps):
        t_prev = timesteps[i + 1] if i + 1 < len(timesteps) else -1
        ab = float(alpha_bar[t])
        ab_prev = float(alpha_bar[t_prev]) if t_prev >= 0 else 1.0
        t_tensor = torch.full((batch,), t, dtype=torch.int64, device=device)

        def denoise(x: torch.Tensor, _t=t_tensor, _ab=ab) -> torch.Tensor:
            return predict_x0(model_fn(x, _t), x, _ab, parameterisation)

        with torch.no_grad():
            x0_hat = denoise(x_t)
        if hook is not None:
            extras = dict(state_extras or {})
            state = GuidanceState(
                step=i,
                steps=len(timesteps),
                t=t,
                t_prev=t_prev,
                alpha_bar=ab,
                alpha_bar_prev=ab_prev,
                sigma=math.sqrt(1.0 - ab),
                x_t=x_t,
                x0_hat=x0_hat,
                denoise=denoise,
                parameterisation=parameterisation,
                projection=extras.pop("projection", None),
                normalise=extras.pop("normalise", lambda x: x),
                denormalise=extras.pop("denormalise", lambda x: x),
                to_features=extras.pop("to_features", lambda x: x),
                from_features=extras.pop("from_features", lambda x: x),
                condition=extras.pop("condition", None),
            )
            hook(state)
            x_t, x0_hat = state.x_t.detach(), state.x0_hat.detach()
        if t_prev < 0:
            break
        with torch.no_grad():
            eps_hat = (x_t - math.sqrt(ab) * x0_hat) / math.sqrt(max(1.0 - ab, 1e-12))
            sigma = 0.0
            if eta > 0:
                sigma = eta * math.sqrt((1 - ab_prev) / (1 - ab)) * math.sqrt(max(1 - ab / ab_prev, 0.0))
            x_t = math.sqrt(ab_prev) * x0_hat + math.sqrt(max(1.0 - ab_prev - sigma**2, 0.0)) * eps_hat
            if sigma > 0:
                x_t = x_t + sigma * torch.randn(shape, generator=generator).to(device=device, dtype=dtype)
    return x0_hat
