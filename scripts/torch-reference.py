"""What PyTorch itself makes of one MDRLAT gradient step, for comparison with `mdrlat bench
train` on the same machine: the network of `python/mdrlat/qnet.py` (the Rust layout), a
double-DQN update of batch B (online forward on s with the auxiliary head, online and target
forwards on s' without a graph, Huber + velocity loss, backward, Adam), timed on each device
and numeric mode given. One JSON object per line.

    python3 scripts/torch-reference.py --devices cuda,cpu --batches 32,512 --seconds 3

Needs only torch and numpy (it loads qnet.py by path, not the compiled `mdrlat` package).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

import torch
import torch.nn.functional as F

ROOT = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("qnet", ROOT / "python" / "mdrlat" / "qnet.py")
qnet = importlib.util.module_from_spec(spec)
spec.loader.exec_module(qnet)

# ~4.47 GFLOP per batch-32 MDRLAT step, as `bench train` counts it (scaled by batch).
GFLOP_PER_SAMPLE = 4.47 / 32


def step_fn(device: torch.device, batch: int):
    torch.manual_seed(0)
    online = qnet.QNet("mdrlat").to(device)
    target = qnet.QNet("mdrlat").to(device)
    target.load_state_dict(online.state_dict())
    opt = torch.optim.Adam(online.parameters(), lr=1e-4)
    g = torch.Generator(device="cpu").manual_seed(1)
    s_l, s2_l = (torch.rand(batch, 4, 512, generator=g).to(device) for _ in range(2))
    s_d, s2_d = (torch.rand(batch, 4, 128, 160, generator=g).to(device) for _ in range(2))
    a = torch.randint(0, 10, (batch,), generator=g).to(device)
    r = torch.randn(batch, generator=g).to(device)
    done = torch.zeros(batch, device=device)
    vel = torch.randn(batch, 6, generator=g).to(device)

    def step():
        with torch.no_grad():
            a2 = online(laser=s2_l, depth=s2_d, normalised=True).argmax(dim=1, keepdim=True)
            q2 = target(laser=s2_l, depth=s2_d, normalised=True).gather(1, a2).squeeze(1)
            y = r + 0.99 * (1 - done) * q2
        h = online.representation(laser=s_l, depth=s_d, normalised=True)
        v, adv = online.value(h), online.advantage(h)
        q = (v + adv - adv.mean(dim=1, keepdim=True)).gather(1, a.unsqueeze(1)).squeeze(1)
        loss = F.huber_loss(q, y) + F.mse_loss(online.velocity(h), vel)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss

    return step


def measure(device: torch.device, batch: int, seconds: float) -> dict:
    step = step_fn(device, batch)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    for _ in range(3):
        step()
    sync()
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        n += 1
        if n % 10 == 0:
            sync()
    sync()
    ms = (time.perf_counter() - start) / n * 1e3
    return {"ms_per_step": round(ms, 2), "steps": n,
            "gflops": round(GFLOP_PER_SAMPLE * batch / ms * 1e3, 1)}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--devices", default="cuda,cpu")
    p.add_argument("--batches", default="32,512")
    p.add_argument("--cpu-threads", default="16,2", help="thread counts for cpu")
    p.add_argument("--seconds", type=float, default=3.0)
    args = p.parse_args()
    for dev in args.devices.split(","):
        if dev == "cuda" and not torch.cuda.is_available():
            print(json.dumps({"device": "cuda", "error": "not available"}))
            continue
        modes = [("fp32", False), ("tf32", True)] if dev == "cuda" else [("fp32", False)]
        threads = [int(t) for t in args.cpu_threads.split(",")] if dev == "cpu" else [None]
        for t in threads:
            if t:
                torch.set_num_threads(t)
            for mode, tf32 in modes:
                torch.backends.cuda.matmul.allow_tf32 = tf32
                torch.backends.cudnn.allow_tf32 = tf32
                for b in (int(x) for x in args.batches.split(",")):
                    if dev == "cpu" and b > 32:
                        continue
                    row = {"bench": "torch_train", "device": dev, "mode": mode, "batch": b,
                           "threads": t, "torch": torch.__version__}
                    row |= measure(torch.device(dev), b, args.seconds)
                    print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
