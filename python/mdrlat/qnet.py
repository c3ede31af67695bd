"""The six networks of the paper in plain PyTorch, loading a run's ``model.safetensors``.

``torch`` is an optional extra (``pip install ./python[torch]``); this module imports it.
The layout follows the Rust network (``crates/mdrlat-nn``) exactly: two convolutional streams
with TensorFlow-"SAME" padding, optional bilinear fusion, the representation
``h = [depth features, fusion, laser features, goal]``, a dueling head (paper eq. 11) and the
auxiliary velocity head (eq. 12). Inputs in metres are normalised as the Rust side does
(laser / 5.6, depth clamped to 0–10 m / 5, goal distance / 10 m).

>>> from mdrlat.qnet import QNet
>>> net = QNet.load("runs/quick")                      # a run, a model folder or a file
>>> q = net(laser=obs["laser"][None], depth=obs["depth"][None])
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

#: What each variant reads and has: (laser, depth, bilinear fusion, auxiliary task).
VARIANTS = {
    "laser-only": (True, False, False, False),
    "depth-only": (False, True, False, False),
    "multi": (True, True, False, False),
    "multi-at": (True, True, False, True),
    "multi-bf": (True, True, True, False),
    "mdrlat": (True, True, True, True),
}
LASER_MAX_M, DEPTH_MAX_M, DEPTH_SCALE_M, GOAL_NORM_M = 5.6, 10.0, 5.0, 10.0
HIDDEN, FUSION_DEPTH, FUSION_LASER, FUSION_OUT, VELOCITY_OUT, ACTIONS = 512, 128, 64, 512, 6, 10


def _same(x: torch.Tensor, kernel: tuple[int, ...], stride: int) -> torch.Tensor:
    """TensorFlow SAME padding on the last ``len(kernel)`` axes (the extra pixel after)."""
    pads: list[int] = []
    for axis, k in zip(range(x.dim() - 1, x.dim() - 1 - len(kernel), -1), reversed(kernel)):
        n = x.shape[axis]
        total = max((-(-n // stride) - 1) * stride + k - n, 0)
        pads += [total // 2, total - total // 2]
    return F.pad(x, pads)


class _Conv(nn.Module):
    def __init__(self, conv: nn.Module, stride: int):
        super().__init__()
        self.conv, self.stride = conv, stride

    def forward(self, x):
        return self.conv(_same(x, self.conv.kernel_size, self.stride))


class _Head(nn.Module):
    def __init__(self, inputs: int, out: int):
        super().__init__()
        self.hidden, self.out = nn.Linear(inputs, HIDDEN), nn.Linear(HIDDEN, out)

    def forward(self, h):
        return self.out(F.relu(self.hidden(h)))


class QNet(nn.Module):
    """One of the six networks (``variant``), with a goal input of ``goal_dim`` (3 for a
    navigation network, else 0)."""

    def __init__(self, variant: str = "mdrlat", goal_dim: int = 0):
        super().__init__()
        if variant not in VARIANTS:
            raise ValueError(f"variant {variant!r}: expected one of {', '.join(VARIANTS)}")
        self.variant, self.goal_dim = variant, goal_dim
        # Frames of the camera's memory in the laser scan it reads (set by `load`).
        self.depth_memory_frames = 0
        laser, depth, fusion, aux = VARIANTS[variant]
        h = goal_dim
        if depth:
            c = lambda i, o, k, s: _Conv(nn.Conv2d(i, o, k, stride=s), s)  # noqa: E731
            self.depth = nn.ModuleDict({"c1": c(4, 16, (10, 14), 8), "c2": c(16, 32, (4, 4), 2), "c3": c(32, 32, (3, 3), 1)})
            h += 32 * 8 * 10
        if laser:
            c = lambda i, o, k, s: _Conv(nn.Conv1d(i, o, k, stride=s), s)  # noqa: E731
            self.laser = nn.ModuleDict({"c1": c(4, 16, 5, 4), "c2": c(16, 32, 3, 2), "c3": c(32, 32, 3, 2)})
            h += 32 * 32
        if fusion:
            self.fusion = nn.ModuleDict({
                "depth": nn.Linear(32 * 8 * 10, FUSION_DEPTH),
                "laser": nn.Linear(32 * 32, FUSION_LASER),
                "out": nn.Linear(FUSION_DEPTH * FUSION_LASER, FUSION_OUT),
            })
            h += FUSION_OUT
        self.value, self.advantage = _Head(h, 1), _Head(h, ACTIONS)
        if aux:
            self.velocity = _Head(h, VELOCITY_OUT)

    @staticmethod
    def _stream(convs: nn.ModuleDict, x):
        for name in ("c1", "c2", "c3"):
            x = F.relu(convs[name](x))
        return x.flatten(1)

    def representation(self, laser=None, depth=None, goal=None, normalised=False):
        """``h`` for a batch: laser ``[B, 4, 512]``, depth ``[B, 4, 128, 160]``, goal
        ``[B, 3]``, in metres (``normalised=False``) or as the network reads them."""
        uses_laser, uses_depth, fusion, _ = VARIANTS[self.variant]
        as_tensor = lambda a: torch.as_tensor(np.asarray(a) if not torch.is_tensor(a) else a, dtype=torch.float32)  # noqa: E731
        parts = []
        if uses_depth:
            if depth is None:
                raise ValueError(f"a {self.variant} network reads the depth camera: give depth")
            d = as_tensor(depth)
            # As mdrlat_core::normalize_depth: NaN (no return) reads 0.
            d = d if normalised else torch.nan_to_num(d, nan=0.0).clamp(0.0, DEPTH_MAX_M) / DEPTH_SCALE_M
            d_feat = self._stream(self.depth, d)
        if uses_laser:
            if laser is None:
                raise ValueError(f"a {self.variant} network reads the laser: give laser")
            l = as_tensor(laser)
            # As mdrlat_core::normalize_laser: a non-finite range reads 1.0, "nothing seen".
            l = l if normalised else torch.where(torch.isfinite(l), l / LASER_MAX_M, 1.0)
            l_feat = self._stream(self.laser, l)
        if uses_depth:
            parts.append(d_feat)
        if fusion:
            d, l = self.fusion["depth"](d_feat), self.fusion["laser"](l_feat)
            outer = (d.unsqueeze(2) * l.unsqueeze(1)).flatten(1)  # d_i · l_j at i·64 + j
            parts.append(F.relu(self.fusion["out"](outer)))
        if uses_laser:
            parts.append(l_feat)
        if self.goal_dim:
            if goal is None:
                raise ValueError("a navigation network reads the goal: give goal")
            g = as_tensor(goal)
            if not normalised:
                g = torch.cat([g[:, :1] / GOAL_NORM_M, g[:, 1:]], dim=1)
                # As mdrlat_core::normalize_goal: a goal with a non-finite part reads [1, 0, 1].
                bad = ~torch.isfinite(g).all(dim=1, keepdim=True)
                g = torch.where(bad, torch.tensor([1.0, 0.0, 1.0]), g)
            parts.append(g)
        return torch.cat(parts, dim=1)

    def forward(self, laser=None, depth=None, goal=None, normalised=False):
        """Q-values ``[B, 10]`` (Table 1 actions), eq. (11)."""
        h = self.representation(laser, depth, goal, normalised)
        v, a = self.value(h), self.advantage(h)
        return v + a - a.mean(dim=1, keepdim=True)

    def velocity_estimate(self, laser=None, depth=None, goal=None, normalised=False):
        """The auxiliary head's ``(v, w)`` at t-2, t-1, t, ``[B, 6]`` (multi-at, mdrlat)."""
        if not hasattr(self, "velocity"):
            raise ValueError(f"a {self.variant} network has no auxiliary velocity head")
        return self.velocity(self.representation(laser, depth, goal, normalised))

    def greedy(self, **inputs) -> np.ndarray:
        """The greedy action of each row (the first maximum on ties, as in Rust)."""
        with torch.no_grad():
            return self(**inputs).argmax(dim=1).numpy()

    @classmethod
    def load(cls, path) -> "QNet":
        """The network of a ``model.safetensors`` (f32 or f16), a model folder holding one
        or a run directory of ``mdrlat train``."""
        path = Path(path)
        if path.is_dir():
            path = path / "model.safetensors"
        tensors, meta = read_safetensors(path)
        variant = meta.get("mdrlat_variant")
        if variant is None:
            raise ValueError(f"{path}: no mdrlat_variant in its metadata: not an mdrlat model")
        net = cls(variant, goal_dim=3 if meta.get("mdrlat_task") == "nav" else 0)
        # The scan it was trained on: feed it from an env made with
        # laser={"depth_memory_frames": net.depth_memory_frames} (0: the laser's own).
        memory = meta.get("mdrlat_depth_memory_frames")
        if memory is not None:
            if not memory.isdigit() or not 1 <= int(memory) <= 64:
                raise ValueError(f"{path}: mdrlat_depth_memory_frames = {memory!r}: not 1 to 64")
            net.depth_memory_frames = int(memory)
        state = {}
        for name, value in tensors.items():
            module, _, param = name.rpartition(".")
            # `laser.c1.weight` is `laser.c1.conv.weight` here (the SAME-padding wrapper).
            if module.startswith(("laser.c", "depth.c")):
                module += ".conv"
            state[f"{module}.{param}"] = torch.from_numpy(value.astype(np.float32))
        missing, unexpected = net.load_state_dict(state, strict=False)
        if missing or unexpected:
            raise ValueError(f"{path}: does not fit a {variant} network (missing {missing}, unexpected {unexpected})")
        return net.eval()


def read_safetensors(path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The tensors (as numpy arrays) and metadata of a safetensors file, without the
    ``safetensors`` package."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) < 8:
        raise ValueError(f"{path}: shorter than a safetensors header")
    (n,) = struct.unpack("<Q", data[:8])
    if n > len(data) - 8:
        raise ValueError(f"{path}: header length {n} beyond the file: not a safetensors file")
    header = json.loads(data[8 : 8 + n])
    meta = header.pop("__metadata__", {}) or {}
    dtypes = {"F32": np.float32, "F16": np.float16}
    out = {}
    for name, t in header.items():
        if t["dtype"] not in dtypes:
            raise ValueError(f"{path}: tensor {name} has dtype {t['dtype']} (expected F32 or F16)")
        start, end = t["data_offsets"]
        out[name] = np.frombuffer(data[8 + n + start : 8 + n + end], dtypes[t["dtype"]]).reshape(t["shape"])
    return out, meta
