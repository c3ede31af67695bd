"""Steps per second from Python beside the Rust figures, in one run (issue 12, item 6).

    python python/benchmarks/speed.py [--mdrlat target/release/mdrlat] [--seconds 2]
        [--rounds 5] [--world train] [--json]

Measures, round after round on the same machine: `mdrlat bench sim --json` (one env, then a
VecEnv of 2 envs per thread on all cores), then `mdrlat.VectorEnv` with the same number of
envs and threads, right after the Rust vector figure, then `mdrlat.MdrlatEnv` (one env,
random actions, reset at episode ends); prints the medians and each Python figure as a
share of its Rust counterpart of the same round (shared virtual machines drift by 10 %
between seconds: rounds side by side; the one-env pair has two measurements between its
halves, the vector pair none). The Python figures include
everything a Gymnasium user pays: the observation arrays (4 laser scans and 4 depth images
per env and step, 336 KB), the info dicts, the autoreset bookkeeping.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import time

import numpy as np

import mdrlat


def rust(mdrlat_bin: str, world: str, seconds: float) -> list[dict]:
    out = subprocess.run(
        [mdrlat_bin, "bench", "sim", "--json", "--worlds", world, "--seconds", str(seconds)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def actions(n: int, envs: int | None = None) -> np.ndarray:
    """Random Table 1 actions, drawn before the clock starts (the Rust benchmark draws its
    own with a few-nanosecond generator; numpy's costs microseconds a call)."""
    rng = np.random.default_rng(0)
    return rng.integers(10, size=n if envs is None else (n, envs))


def single(world: str, seconds: float) -> float:
    env = mdrlat.make(world)
    env.reset(seed=0)
    acts = [int(a) for a in actions(4096)]
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for a in acts[:256]:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        steps += 256
        acts = acts[256:] + acts[:256]
    return steps / (time.perf_counter() - t0)


def vector(world: str, envs: int, threads: int, seconds: float) -> float:
    vec = mdrlat.VectorEnv(world, num_envs=envs, threads=threads)
    vec.reset(seed=0)
    acts = actions(4096, envs)
    steps, t0, k = 0, time.perf_counter(), 0
    while time.perf_counter() - t0 < seconds:
        for a in acts[k : k + 64]:
            vec.step(a)
        steps += 64 * envs
        k = (k + 64) % len(acts)
    vec.close()
    return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mdrlat", default="target/release/mdrlat", help="the mdrlat binary")
    ap.add_argument("--world", default="train")
    ap.add_argument("--seconds", type=float, default=2.0, help="seconds per measurement")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of all four measurements")
    ap.add_argument("--json", action="store_true", help="one JSON object per line")
    a = ap.parse_args()
    one, many = [], []
    for _ in range(a.rounds):
        rows = rust(a.mdrlat, a.world, a.seconds)
        r1 = next(r for r in rows if r["envs"] == 1)
        rn = next(r for r in rows if r["envs"] > 1)
        envs, threads = rn["envs"], rn["threads"]
        # The vector env right after `bench sim`'s own vector measurement (its last), so
        # that the pair the target compares is measured back to back.
        many.append((rn["steps_per_s"], vector(a.world, envs, threads, a.seconds)))
        one.append((r1["steps_per_s"], single(a.world, a.seconds)))
    med = lambda xs: float(np.median(xs))  # noqa: E731
    results = [
        ("one env", 1, 1, one),
        (f"vector, {envs} envs on {threads} threads", envs, threads, many),
    ]
    if a.json:
        for name, e, t, pairs in results:
            print(json.dumps({
                "bench": "python_sim", "world": a.world, "envs": e, "threads": t,
                "rust_steps_per_s": med([r for r, _ in pairs]),
                "python_steps_per_s": med([p for _, p in pairs]),
                "ratio": med([p / r for r, p in pairs]),
                "rounds": a.rounds,
            }))
        return
    print(f"{cpu()}, world {a.world}, {a.rounds} rounds of {a.seconds} s, medians")
    print("| measurement | Rust steps/s | Python steps/s | Python / Rust (per round) |")
    print("| --- | --- | --- | --- |")
    for name, _, _, pairs in results:
        ratios = [p / r for r, p in pairs]
        print(
            f"| {name} | {med([r for r, _ in pairs]):.0f} | {med([p for _, p in pairs]):.0f} "
            f"| {med(ratios):.2f} ({min(ratios):.2f}–{max(ratios):.2f}) |"
        )


def cpu() -> str:
    """The CPU's model name (as lscpu prints it)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


if __name__ == "__main__":
    main()
