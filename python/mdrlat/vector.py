"""N environments stepped in Rust on all cores: a `gymnasium.vector.VectorEnv`.

The Rust `VecEnv` steps every environment with the GIL released and writes the
observations into numpy buffers this object keeps: the arrays ``step`` returns are the same
every step (copy them to keep them). Finished episodes restart in the same step
(``AutoresetMode.SAME_STEP``): their final observation and info are in
``infos["final_obs"]`` / ``infos["final_info"]``, masked by ``infos["_final_obs"]``, as
Gymnasium's own vector environments write them. Seeding follows Gymnasium: ``reset(seed=s)``
starts environment ``i`` as ``MdrlatEnv.reset(seed=s + i)`` would.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv as GymVectorEnv
from gymnasium.vector.utils import batch_space

from . import _core
from .env import MdrlatEnv, _settings


class VectorEnv(GymVectorEnv):
    """``num_envs`` robots in ``world`` (as :class:`mdrlat.MdrlatEnv`), stepped on
    ``threads`` threads (0: every core)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, world: str = "train", num_envs: int = 1, threads: int = 0, **overrides: Any):
        if "task" in overrides:
            overrides["task"] = _core.check_task(str(overrides["task"]))
        self.single = MdrlatEnv(world, **overrides)  # the spaces, and checks the arguments
        self._venv = _core.VecEnv(str(world), _settings(overrides), int(num_envs), int(threads))
        self.num_envs = int(num_envs)
        self.single_observation_space = self.single.observation_space
        self.single_action_space = self.single.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n = self.num_envs
        laser, depth, odom, goal = _core.shapes()
        self._obs = {
            "laser": np.zeros((n, *laser), np.float32),
            "depth": np.zeros((n, *depth), np.float32),
            "odom": np.zeros((n, odom), np.float32),
        }
        nav = self._venv.task == "nav"
        self._goal = np.zeros((n if nav else 0, goal), np.float32)
        if nav:
            self._obs["goal"] = self._goal
        self._rewards = np.zeros(n, np.float32)
        self._terminated = np.zeros(n, np.bool_)
        self._truncated = np.zeros(n, np.bool_)
        self._d_min = np.zeros(n, np.float32)
        self._buffers = {
            "laser": self._obs["laser"],
            "depth": self._obs["depth"],
            "odom": self._obs["odom"],
            "goal": self._goal,
        }
        self._started = False

    @property
    def threads(self) -> int:
        """Threads stepping the environments."""
        return self._venv.threads

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Starts an episode everywhere; ``seed`` an int (environment ``i`` gets
        ``seed + i``), a list of one seed (or None) per environment, or None."""
        if options:
            raise ValueError(f"reset options {sorted(options)}: the vector env takes none")
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        for s in seeds:
            if s is not None and not 0 <= s < 2**64:
                raise ValueError(f"seed {s}: expected 0 to 2**64 - 1")
        poses = self._venv.reset(seeds, self._buffers)
        self._started = True
        return self._obs, {"pose": np.array(poses, np.float32), "_pose": np.ones(self.num_envs, np.bool_)}

    def step(self, actions):
        """One step of every environment with ``actions`` (one Table 1 index each)."""
        if not self._started:
            raise RuntimeError("step() before reset(): call reset() first")
        a = np.ascontiguousarray(actions, dtype=np.int64).reshape(-1)
        ended = self._venv.step(
            a, self._buffers, self._rewards, self._terminated, self._truncated, self._d_min
        )
        infos: dict[str, Any] = {"d_min": self._d_min.copy(), "_d_min": np.ones(self.num_envs, np.bool_)}
        for i, final_obs, final_info in ended:
            infos = self._add_info(infos, {"final_obs": final_obs, "final_info": final_info}, i)
        return self._obs, self._rewards, self._terminated, self._truncated, infos

    def close_extras(self, **kwargs):
        self._venv = None
