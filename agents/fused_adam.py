"""Adam's update as one fused kernel per step where torch has one for the device.

rsl-rl builds ``torch.optim.Adam`` with torch's defaults, which on a CPU is the
single-tensor implementation: a Python loop of about ten small operations per parameter
tensor per step, about a sixth of a camera update's time on a CPU (see
``benchmarks/RESULTS.md``, "Adam fused"). The fused kernel computes the same update.
"""

from __future__ import annotations

import torch

FUSED_DEVICES = ("cpu", "cuda")  # where torch (2.4 and later) has a fused Adam


def fuse_adam(optimizer: torch.optim.Optimizer) -> None:
    """Switch an Adam (or AdamW) optimizer to torch's fused implementation in place.

    Also after ``load_state_dict``, which restores the saved groups' settings: a checkpoint
    from before this switch brings back the unfused one. Other optimizers, and parameters
    on a device without the kernel, are left as they are.
    """
    if not isinstance(optimizer, torch.optim.Adam | torch.optim.AdamW):
        return
    for group in optimizer.param_groups:
        params = group["params"]
        if group.get("differentiable") or any(p.device.type not in FUSED_DEVICES for p in params):
            continue
        group["fused"], group["foreach"] = True, False
        for p in params:
            state = optimizer.state.get(p)
            if state and "step" in state:
                state["step"] = state["step"].to(device=p.device, dtype=torch.float32)
