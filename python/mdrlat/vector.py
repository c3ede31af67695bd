"""N environments stepped in Rust on all cores: a `gymnasium.vector.VectorEnv`.

The Rust `VecEnv` steps every environment with the GIL released and writes the
observations into numpy buffers this object keeps. Each environment's laser scans and depth
images live in a window buffer of 32 frames: an observation's ``laser`` and ``depth`` are
views of 4 consecutive frames of it, and a step writes the one new frame and moves the view
on, instead of copying all four (a whole stack only after a reset, and every 28 steps when
the view starts again at the front); each environment's thread writes its own rows right
after its step. The final observations of ended episodes are views of buffers too (row
``i`` for environment ``i``, rewritten when its next episode ends). So the arrays ``step``
returns are views into memory that later steps overwrite: copy what you keep.

Finished episodes restart in the same step (``AutoresetMode.SAME_STEP``): their final
observation and info are in ``infos["final_obs"]`` / ``infos["final_info"]``, masked by
``infos["_final_obs"]``, as Gymnasium's own vector environments write them. Seeding follows Gymnasium: ``reset(seed=s)``
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
        (stack, beams), (_, rows, cols), odom, goal = _core.shapes()
        frames = _core.window_frames()
        self._stack = stack
        nav = self._venv.task == "nav"
        self._goal = np.zeros((n if nav else 0, goal), np.float32)
        self._rewards = np.zeros(n, np.float32)
        self._terminated = np.zeros(n, np.bool_)
        self._truncated = np.zeros(n, np.bool_)
        self._d_min = np.zeros(n, np.float32)
        self._buffers = {
            "laser": np.zeros((n, frames, beams), np.float32),
            "depth": np.zeros((n, frames, rows, cols), np.float32),
            "odom": np.zeros((n, odom), np.float32),
            "goal": self._goal,
            "final_laser": np.zeros((n, stack, beams), np.float32),
            "final_depth": np.zeros((n, stack, rows, cols), np.float32),
            "final_odom": np.zeros((n, odom), np.float32),
            "final_goal": np.zeros_like(self._goal),
        }
        self._final_keys = [k for k in ("laser", "depth", "odom", "goal") if k != "goal" or nav]
        self._all = np.ones(n, np.bool_)
        # The observation dicts of every window position, made once.
        self._windows = [self._window(o) for o in range(frames - stack + 1)]
        self._obs = self._windows[0]
        self._started = False

    def _window(self, offset: int) -> dict[str, np.ndarray]:
        """The observations: frames ``offset`` to ``offset + 4`` of the window buffers."""
        b, end = self._buffers, offset + self._stack
        obs = {"laser": b["laser"][:, offset:end], "depth": b["depth"][:, offset:end], "odom": b["odom"]}
        if len(self._goal):
            obs["goal"] = self._goal
        return obs

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
        self._obs = self._windows[0]
        self._started = True
        return self._obs, {"pose": np.array(poses, np.float32), "_pose": np.ones(self.num_envs, np.bool_)}

    def step(self, actions):
        """One step of every environment with ``actions`` (one Table 1 index each)."""
        if not self._started:
            raise RuntimeError("step() before reset(): call reset() first")
        a = np.ascontiguousarray(actions, dtype=np.int64).reshape(-1)
        offset, ended = self._venv.step(
            a, self._buffers, self._rewards, self._terminated, self._truncated, self._d_min
        )
        self._obs = self._windows[offset]
        infos: dict[str, Any] = {"d_min": self._d_min.copy(), "_d_min": self._all.copy()}
        if ended:
            self._add_finals(infos, ended)
        return self._obs, self._rewards, self._terminated, self._truncated, infos

    def _add_finals(self, infos: dict[str, Any], ended: list[tuple[int, dict[str, Any]]]) -> None:
        """``infos["final_obs"]`` and ``infos["final_info"]`` with their masks, exactly as
        Gymnasium's ``VectorEnv._add_info`` builds them (tested), in one pass."""
        n, b = self.num_envs, self._buffers
        final_obs = np.full(n, None, dtype=object)
        mask = np.zeros(n, np.bool_)
        final_info: dict[str, Any] = {}
        for i, info in ended:
            final_obs[i] = {k: b["final_" + k][i] for k in self._final_keys}
            mask[i] = True
            for key, value in info.items():
                if key not in final_info:
                    scalar = type(value) in (int, float, bool)
                    final_info[key] = np.zeros(n, type(value)) if scalar else np.full(n, None, object)
                    final_info["_" + key] = np.zeros(n, np.bool_)
                final_info[key][i] = value
                final_info["_" + key][i] = True
        infos["final_obs"], infos["_final_obs"] = final_obs, mask
        infos["final_info"], infos["_final_info"] = final_info, mask.copy()

    def close_extras(self, **kwargs):
        self._venv = None
