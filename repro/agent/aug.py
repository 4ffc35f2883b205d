"""Random shift augmentation (DrQ-v2): replicate-pad by 4 pixels, then crop back at an integer offset."""

from __future__ import annotations

import torch
import torch.nn.functional as F


class RandomShift:
    """Shift every image of a batch by its own integer offset in [-pad, pad] in each axis; uint8 frames are
    converted to float32 first (a float32 batch is used as it is)."""

    def __init__(self, pad: int = 4):
        self.pad = pad

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        x = x.float()
        n, c, h, w = x.shape
        padded = F.pad(x, (self.pad,) * 4, mode="replicate")
        offsets = torch.randint(0, 2 * self.pad + 1, (n, 2), device=x.device)
        rows = offsets[:, 0:1] + torch.arange(h, device=x.device)[None]  # (n, h)
        cols = offsets[:, 1:2] + torch.arange(w, device=x.device)[None]  # (n, w)
        batch = torch.arange(n, device=x.device)[:, None, None]
        out = padded.permute(0, 2, 3, 1)[batch, rows[:, :, None], cols[:, None, :]]  # (n, h, w, c)
        return out.permute(0, 3, 1, 2).contiguous()
