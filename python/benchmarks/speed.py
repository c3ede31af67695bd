"""Steps per second from Python beside the Rust figures, in one run (issue 12, item 6).

    python python/benchmarks/speed.py [--mdrlat target/release/mdrlat] [--seconds 3] [--world train]

Measures, in this order and on the same machine: `mdrlat bench sim --json` (one env, and a
VecEnv of 2 envs per thread on all cores), then `mdrlat.MdrlatEnv` (one env, random actions,
reset at episode ends) and `mdrlat.VectorEnv` with the same number of envs and threads,
and prints each Python figure as a share of its Rust counterpart. The Python figures include
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


def single(world: str, seconds: float) -> float:
    env = mdrlat.make(world)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        _, _, term, trunc, _ = env.step(int(rng.integers(10)))
        steps += 1
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def vector(world: str, envs: int, threads: int, seconds: float) -> float:
    vec = mdrlat.VectorEnv(world, num_envs=envs, threads=threads)
    vec.reset(seed=0)
    rng = np.random.default_rng(0)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        vec.step(rng.integers(10, size=envs))
        steps += envs
    return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mdrlat", default="target/release/mdrlat", help="the mdrlat binary")
    ap.add_argument("--world", default="train")
    ap.add_argument("--seconds", type=float, default=3.0)
    a = ap.parse_args()
    rows = rust(a.mdrlat, a.world, a.seconds)
    one = next(r for r in rows if r["envs"] == 1)
    many = next(r for r in rows if r["envs"] > 1)
    py_one = single(a.world, a.seconds)
    py_many = vector(a.world, many["envs"], many["threads"], a.seconds)
    print(f"{platform.processor() or platform.machine()}, world {a.world}, {a.seconds} s each")
    print("| measurement | Rust steps/s | Python steps/s | Python / Rust |")
    print("| --- | --- | --- | --- |")
    print(f"| one env | {one['steps_per_s']:.0f} | {py_one:.0f} | {py_one / one['steps_per_s']:.2f} |")
    print(
        f"| vector, {many['envs']} envs on {many['threads']} threads | {many['steps_per_s']:.0f} "
        f"| {py_many:.0f} | {py_many / many['steps_per_s']:.2f} |"
    )


if __name__ == "__main__":
    main()
