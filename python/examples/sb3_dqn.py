"""Stable-Baselines3's DQN on an mdrlat world (issue 12, item 7).

    pip install './python[torch]' stable-baselines3
    python python/examples/sb3_dqn.py [--steps 3000] [--world train]

SB3's `MultiInputPolicy` reads the Dict observation (laser, depth, odom) with its own
`CombinedExtractor` (each part flattened: not the paper's network; see `mdrlat train` for
MDRLAT itself). The replay buffer is kept small: one transition is two 336 KB observations.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
from stable_baselines3 import DQN

import mdrlat  # noqa: F401  (registers the ids)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--world", default="train")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    env = mdrlat.make(a.world)
    model = DQN(
        "MultiInputPolicy",
        env,
        buffer_size=1000,
        learning_starts=500,
        batch_size=32,
        seed=a.seed,
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=a.steps)
    took = time.perf_counter() - t0
    obs, _ = env.reset(seed=a.seed + 1)
    ret, steps, done = 0.0, 0, False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(int(action))
        ret, steps, done = ret + reward, steps + 1, terminated or truncated
    print(
        f"DQN MultiInputPolicy: {a.steps} steps in {took:.0f} s ({a.steps / took:.0f} steps/s); "
        f"greedy episode: {steps} steps, return {ret:.2f}, collision {info['collision']}"
    )


if __name__ == "__main__":
    main()
