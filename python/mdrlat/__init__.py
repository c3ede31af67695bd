"""mdrlat: the MDRLAT simulator (Song et al., Sensors 2021) as Gymnasium environments.

>>> import gymnasium, mdrlat
>>> env = gymnasium.make("mdrlat/Train-v0")
>>> obs, info = env.reset(seed=0)

``mdrlat.make(world, **settings)`` takes any built-in world, world file or map_server map;
``gymnasium.make_vec("mdrlat/Train-v0", num_envs=N)`` or ``mdrlat.VectorEnv(world, N)`` steps
N of them in Rust on every core.
"""

from __future__ import annotations

import gymnasium as gym

from . import _core
from .env import ACTIONS, MdrlatEnv
from .vector import VectorEnv

__version__ = _core.__version__
__all__ = ["ACTIONS", "MdrlatEnv", "VectorEnv", "make", "ENV_IDS"]

#: The registered ids: one per built-in world (the navigation worlds with the nav task).
ENV_IDS = {
    "mdrlat/Train-v0": {"world": "train"},
    "mdrlat/Office-v0": {"world": "office"},
    "mdrlat/Furnished-v0": {"world": "furnished"},
    "mdrlat/Crowd-v0": {"world": "crowd"},
    "mdrlat/NavTrain-v0": {"world": "nav-train", "task": "nav"},
    "mdrlat/NavTest-v0": {"world": "nav-test", "task": "nav"},
}


def make(world: str = "train", render_mode: str | None = None, **settings) -> MdrlatEnv:
    """An environment in ``world`` (built-in name, ``.toml`` world file or map_server
    ``.yaml``) with simulator ``settings`` (``[sim]`` keys, sections as dicts)."""
    return MdrlatEnv(world, render_mode=render_mode, **settings)


def _register() -> None:
    for env_id, kwargs in ENV_IDS.items():
        if env_id not in gym.registry:
            # The time limit is the simulator's own (truncated = True), not a wrapper's.
            gym.register(
                id=env_id,
                entry_point="mdrlat.env:MdrlatEnv",
                vector_entry_point="mdrlat.vector:VectorEnv",
                kwargs=kwargs,
            )


_register()
