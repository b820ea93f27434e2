"""GMD's emphasis projection of the motion representation.

The diffusion model works on ``x_proj = A x / sqrt(N - k + k c^2)`` instead of ``x``
(both ``[..., T, N]``, ``N`` = feature dims, ``x`` the *normalised* features), with
``A = A' B``: ``A'`` a fixed-seed standard-normal ``N x N`` matrix and ``B`` diagonal with
``c`` on the ``k`` emphasised (root-trajectory) dimensions and 1 elsewhere.  Every output
dimension then mixes all input dimensions, with the root trajectory weighted ``c`` times
more, so noise cannot hide the trajectory in a handful of dimensions, and, for inputs of
unit variance per dimension, the output variance per dimension stays ~1 (the scale factor
is the expected squared row norm of ``A' B``).

``A^-1`` is kept (computed in float64) so a guidance hook can impute values in the
original space: ``x = unproject(x_proj)``, edit, ``x_proj = project(x)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn


class EmphasisProjection(nn.Module):
    """Invertible linear projection along the last axis (feature dims).

    Buffers (float64, saved with the model so a checkpoint does not depend on the RNG):
    ``matrix`` = ``A / sqrt(N - k + k c^2)`` ``[N, N]`` and ``inverse`` = its inverse.
    """

    def __init__(self, dim: int, dims: Sequence[int], c: float = 5.0, seed: int = 0):
        super().__init__()
        self.dim = int(dim)
        self.dims = tuple(int(d) for d in dims)
        self.c = float(c)
        generator = torch.Generator().manual_seed(int(seed))
        a_prime = torch.randn(self.dim, self.dim, generator=generator, dtype=torch.float64)
        b = torch.ones(self.dim, dtype=torch.float64)
        b[list(self.dims)] = self.c
        k = len(set(self.dims))
        scale = math.sqrt(self.dim - k + k * self.c**2)
        matrix = a_prime * b[None, :] / scale  # A' B / sqrt(N - k + k c^2)
        self.register_buffer("matrix", matrix)
        self.register_buffer("inverse", torch.linalg.inv(matrix))

    def project(self, x: torch.Tensor) -> torch.Tensor:
        """``x [..., N]`` (normalised features) -> ``x_proj [..., N]``, same dtype (differentiable)."""
        return (x.to(torch.float64) @ self.matrix.T).to(x.dtype)

    def unproject(self, x_proj: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`project`: ``x_proj [..., N]`` -> ``x [..., N]`` (differentiable)."""
        return (x_proj.to(torch.float64) @ self.inverse.T).to(x_proj.dtype)

    def extra_repr(self) -> str:
        return f"dim={self.dim}, emphasised={list(self.dims)}, c={self.c}"
