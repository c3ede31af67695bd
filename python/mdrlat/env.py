"""The simulator as a `gymnasium.Env` (paper section 2; the repository's SPEC §2).

Observations are the networks' inputs before normalisation, in metres, frame stacks oldest
first: ``laser`` (4, 512), ``depth`` (4, 128, 160), ``odom`` (6: v, w at t-2, t-1, t) and,
navigating, ``goal`` (3: distance m, sin and cos of the bearing in the robot frame). Actions
are the ten of the paper's Table 1. ``terminated`` is a collision (or the goal reached),
``truncated`` the time limit; ``info`` has the pose ``(x, y, yaw_deg)``, the velocity,
``d_min`` and the collision kind (``bumper``, ``pedestrian``, ``laser`` or None).
"""

from __future__ import annotations

import json
import operator
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import _core

#: The ten (v m/s, w rad/s) commands of the paper's Table 1, by action index.
ACTIONS = tuple(_core.actions())


def _action_index(action: Any) -> int | None:
    """``action`` as an int where it is one (a Python or NumPy integer, or an integer array
    of one element), else None: a float such as 1.5 is refused, not truncated."""
    if isinstance(action, np.ndarray) and action.size == 1 and action.dtype.kind in "iu":
        return int(action.reshape(()))
    try:
        return operator.index(action)
    except TypeError:
        return None


def _settings(overrides: dict[str, Any]) -> str:
    """Simulator settings (``[sim]`` keys of ``mdrlat config default``; sections as dicts)
    as the JSON the Rust side reads; unknown keys are errors there, naming the key."""
    try:
        return json.dumps(overrides)
    except TypeError as e:
        raise ValueError(f"simulator settings: {e}") from None


class MdrlatEnv(gym.Env):
    """One robot in one world.

    ``world`` is a built-in name (``train``, ``office``, ``furnished``, ``crowd``,
    ``nav-train``, ``nav-test``, ``example``), a ``.toml`` world file or a map_server
    ``.yaml``; ``overrides`` are simulator settings, e.g. ``max_episode_steps=300``,
    ``task="nav"`` or ``laser={"noise_std_m": 0.0}``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(self, world: str = "train", render_mode: str | None = None, **overrides: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}: expected None or 'rgb_array'")
        if "task" in overrides:
            overrides["task"] = _core.check_task(str(overrides["task"]))
        self._env = _core.Env(str(world), _settings(overrides))
        self._world, self._overrides = str(world), dict(overrides)
        self.render_mode = render_mode
        laser_shape, depth_shape, odom_len, goal_len = _core.shapes()
        laser_max, depth_max = self._env.max_ranges
        # Odometry (v, w) stays within Table 1's speeds (the robot accelerates between them);
        # 1 cm/s and 0.01 rad/s of slack for rounding.
        v_max = max(v for v, _ in ACTIONS) + 0.01
        w_max = max(abs(w) for _, w in ACTIONS) + 0.01
        odom_bound = np.tile(np.array([v_max, w_max], np.float32), odom_len // 2)
        parts = {
            "laser": spaces.Box(0.0, laser_max, laser_shape, np.float32),
            "depth": spaces.Box(0.0, depth_max, depth_shape, np.float32),
            "odom": spaces.Box(-odom_bound, odom_bound, (odom_len,), np.float32),
        }
        if self._env.task == "nav":
            # Distance (no farther than the world's diagonal), sin and cos of the bearing.
            far = self._env.world_diagonal
            low = np.array([0.0, -1.0, -1.0], np.float32)
            high = np.array([far, 1.0, 1.0], np.float32)
            parts["goal"] = spaces.Box(low, high, (goal_len,), np.float32)
        self.observation_space = spaces.Dict(parts)
        self.action_space = spaces.Discrete(len(ACTIONS))

    @property
    def world_name(self) -> str:
        """The world's name."""
        return self._env.world_name

    @property
    def task(self) -> str:
        """``avoid`` or ``nav``."""
        return self._env.task

    @property
    def max_episode_steps(self) -> int:
        """Steps after which an episode is truncated."""
        return self._env.max_episode_steps

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts an episode from ``seed``'s start pose, or at ``options["pose"]`` =
        ``(x, y, yaw_deg)``."""
        super().reset(seed=seed)
        options = dict(options or {})
        pose = options.pop("pose", None)
        if options:
            raise ValueError(f"reset options {sorted(options)}: only 'pose' is known")
        if pose is not None:
            try:
                x, y, yaw = (float(v) for v in pose)
            except (TypeError, ValueError):
                raise ValueError(f"options['pose'] {pose!r}: expected (x, y, yaw_deg)") from None
            pose = (x, y, yaw)
        if seed is not None and not 0 <= int(seed) < 2**64:
            raise ValueError(f"seed {seed}: expected 0 to 2**64 - 1")
        return self._env.reset(None if seed is None else int(seed), pose)

    def step(self, action):
        """One control period (0.2 s) with Table 1 action ``action``."""
        a = _action_index(action)
        if a is None or not self.action_space.contains(a):
            raise ValueError(f"action {action!r}: expected an integer 0 to 9")
        obs, reward, terminated, truncated, info = self._env.step(a)
        return obs, float(reward), terminated, truncated, info

    def render(self):
        """The top view with the depth image beside it, ``(H, W, 3)`` uint8."""
        if self.render_mode == "rgb_array":
            return self._env.render()
        return None

    def close(self):
        pass

    def __getstate__(self):
        # The Rust state is rebuilt from the world and settings; an episode in progress is
        # not carried over (reset after unpickling, as after construction).
        return {"world": self._world, "overrides": self._overrides, "render_mode": self.render_mode}

    def __setstate__(self, state):
        self.__init__(state["world"], state["render_mode"], **state["overrides"])
