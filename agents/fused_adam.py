"""Adam's update as one fused kernel per step where torch has one for the device.

rsl-rl builds ``torch.optim.Adam`` with torch's defaults, which on a CPU is the
single-tensor implementation: a loop of about ten small operations per weight tensor per
step, 17% of a profiled camera update on a CPU (``benchmarks/RESULTS.md``, "Adam in one
kernel"). The fused kernel computes the same update in one call.
"""

from __future__ import annotations

import functools

import torch


@functools.cache
def has_fused_adam(device_type: str) -> bool:
    """Whether this torch has a fused Adam kernel for ``device_type`` (``"cpu"``, ...)."""
    try:
        torch.optim.Adam([torch.zeros(1, device=device_type, requires_grad=True)], fused=True)
    except Exception:  # a capability probe: any refusal means no kernel here
        return False
    return True


def fuse_adam(optimizer: torch.optim.Optimizer) -> None:
    """Switch an Adam (or AdamW) optimizer to torch's fused implementation in place.

    Call it again after ``load_state_dict``, which restores the saved groups' settings: a
    checkpoint from before this switch brings back the unfused one. Other optimizers, and
    parameters on a device without the kernel, are left as they are.
    """
    if not isinstance(optimizer, torch.optim.Adam | torch.optim.AdamW):
        return
    for group in optimizer.param_groups:
        params = group["params"]
        if group.get("differentiable") or not all(has_fused_adam(p.device.type) for p in params):
            continue
        group["fused"], group["foreach"] = True, False
        for p in params:
            state = optimizer.state.get(p)
            if state and "step" in state:
                state["step"] = state["step"].to(device=p.device, dtype=torch.float32)
