"""N environments stepped in Rust on all cores: a `gymnasium.vector.VectorEnv`.

The Rust `VecEnv` steps every environment with the GIL released and writes the
observations into numpy buffers of its own, made once; one Rust call per step returns
Gymnasium's tuple, so that little Python runs between steps while the worker threads
wait. Each environment's laser scans and depth images live in a window buffer of 16
frames: an observation's ``laser`` and ``depth`` are views of 4 consecutive frames of it,
and a step writes the one new frame and moves the view on, instead of copying all four (a
whole stack only after a reset, and every 13 steps when the view starts again at the
front); each environment's thread writes its own rows right after its step. The final
observations of ended episodes are views of buffers too (row ``i`` for environment ``i``,
rewritten when its next episode ends). So the arrays ``step`` returns are views into
memory that later steps overwrite: copy what you keep.

Finished episodes restart in the same step (``AutoresetMode.SAME_STEP``): their final
observation and info are in ``infos["final_obs"]`` / ``infos["final_info"]``, masked by
``infos["_final_obs"]``, as Gymnasium's own vector environments write them. Seeding
follows Gymnasium: ``reset(seed=s)`` starts environment ``i`` as ``MdrlatEnv.reset(seed=s +
i)`` would.
"""

from __future__ import annotations

import operator
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
        num_envs = _count("num_envs", num_envs, 1, _core.MAX_ENVS)
        threads = _count("threads", threads, 0, _core.MAX_ENVS)
        self.single = MdrlatEnv(world, **overrides)  # the spaces, and checks the arguments
        self._venv = _core.VecEnv(str(world), _settings(overrides), num_envs, threads)
        self._threads_asked = threads
        self.num_envs = num_envs
        self.single_observation_space = self.single.observation_space
        self.single_action_space = self.single.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        nav = self._venv.task == "nav"
        b = self._venv.buffers()
        keys = [k for k in ("laser", "depth", "odom", "goal") if k != "goal" or nav]
        # Environment i's final observation: row i of the `final_*` buffers.
        self._final_views = [{k: b["final_" + k][i] for k in keys} for i in range(self.num_envs)]
        self._none = np.full(self.num_envs, None, object)
        self._false = np.zeros(self.num_envs, np.bool_)

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
        obs, poses = self._venv.reset(seeds)
        return obs, {"pose": np.array(poses, np.float32), "_pose": np.ones(self.num_envs, np.bool_)}

    def step(self, actions):
        """One step of every environment with ``actions`` (one Table 1 index each)."""
        try:
            # The whole step is one Rust call: the observations, rewards and flags are
            # its own buffers, the infos its dict; only ended episodes come back here.
            obs, rewards, terminated, truncated, infos, ended = self._venv.step(actions)
        except TypeError:  # not an int64 array
            a = np.asarray(actions)
            if a.dtype.kind not in "iu":
                raise ValueError(
                    f"actions {actions!r}: expected {self.num_envs} integers 0 to 9"
                ) from None
            a = np.ascontiguousarray(a, dtype=np.int64)
            obs, rewards, terminated, truncated, infos, ended = self._venv.step(a)
        if ended:
            self._add_finals(infos, ended)
        return obs, rewards, terminated, truncated, infos

    def _add_finals(self, infos: dict[str, Any], ended: list[tuple[int, dict[str, Any]]]) -> None:
        """``infos["final_obs"]`` and ``infos["final_info"]`` with their masks, exactly as
        Gymnasium's ``VectorEnv._add_info`` builds them (tested), in one pass. The arrays
        are copies of ones made once (``np.full(n, None, object)`` costs 5x a copy)."""
        none, false = self._none, self._false
        final_obs, mask = none.copy(), false.copy()
        final_info: dict[str, Any] = {}
        for i, info in ended:
            final_obs[i] = dict(self._final_views[i])
            mask[i] = True
            for key, value in info.items():
                if key not in final_info:
                    scalar = type(value) in (int, float, bool)
                    final_info[key] = np.zeros(len(none), type(value)) if scalar else none.copy()
                    final_info["_" + key] = false.copy()
                final_info[key][i] = value
                final_info["_" + key][i] = True
        infos["final_obs"], infos["_final_obs"] = final_obs, mask
        infos["final_info"], infos["_final_info"] = final_info, mask.copy()

    def close_extras(self, **kwargs):
        self._venv = _Closed()

    def __getstate__(self):
        # As for MdrlatEnv: the Rust environments are rebuilt from the world and settings,
        # open and not yet reset (episodes in progress are not carried over).
        return {
            "world": self.single._world,
            "num_envs": self.num_envs,
            "threads": self._threads_asked,
            "overrides": self.single._overrides,
        }

    def __setstate__(self, state):
        self.__init__(state["world"], state["num_envs"], state["threads"], **state["overrides"])


def _count(name: str, value: Any, least: int, most: int) -> int:
    """An integer argument from ``least`` to ``most``, or a ValueError naming it."""
    try:
        n = None if isinstance(value, (bool, np.bool_)) else operator.index(value)
    except TypeError:
        n = None
    if n is None:
        raise ValueError(f"{name} {value!r}: expected an integer")
    if not least <= n <= most:
        raise ValueError(f"{name} {n}: expected {least} to {most}")
    return n


class _Closed:
    """The Rust environments of a closed :class:`VectorEnv`: gone, so any use is an error
    that says so (not an AttributeError on None)."""

    def __getattr__(self, name: str):
        if name.startswith("__"):  # copy, pickle and friends probe for these
            raise AttributeError(name)
        raise RuntimeError("this VectorEnv is closed: make a new one")
