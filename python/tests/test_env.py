"""The Gymnasium environments: the ecosystem's own checker, determinism, pickling, dtypes and
bounds, and bad input as Python exceptions."""

import copy
import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mdrlat

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("env_id", sorted(mdrlat.ENV_IDS))
def test_every_registered_id_passes_gymnasiums_checker(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checker's warnings are failures here
        check_env(env.unwrapped)
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()


def rollout(env, seed, steps=120):
    """Observations, rewards and flags of `steps` steps of a seeded action sequence."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(int(rng.integers(10)))
        out.append((obs, r, term, trunc, info["collision"]))
        if term or trunc:
            obs, _ = env.reset()
            out.append(obs)
    return out


def same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    if isinstance(a, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def test_the_same_seed_gives_the_same_arrays():
    a = rollout(mdrlat.make("crowd"), 3)
    b = rollout(mdrlat.make("crowd"), 3)
    assert len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    c = rollout(mdrlat.make("crowd"), 4)
    assert not same(a[0], c[0]), "another seed, another start"


def test_observations_have_the_documented_shapes_dtypes_and_units():
    env = mdrlat.make("train")
    obs, info = env.reset(seed=0)
    assert obs["laser"].shape == (4, 512) and obs["depth"].shape == (4, 128, 160)
    assert obs["odom"].shape == (6,)
    assert all(v.dtype == np.float32 for v in obs.values())
    assert env.observation_space.contains(obs)
    assert 0.0 < obs["laser"].max() <= 5.6 and 0.0 <= obs["depth"].min()
    assert set(info) >= {"pose", "step"}
    obs, r, term, trunc, info = env.step(0)
    assert isinstance(r, float) and isinstance(term, bool) and isinstance(trunc, bool)
    assert set(info) >= {"pose", "velocity", "d_min", "collision"}
    # Table 1: action 1 drives straight at 0.5 m/s; 8 and 9 turn on the spot at π/3 rad/s.
    assert len(mdrlat.ACTIONS) == 10 and mdrlat.ACTIONS[1] == pytest.approx((0.5, 0.0))
    assert mdrlat.ACTIONS[9] == pytest.approx((0.0, np.pi / 3))


def test_a_pose_starts_the_episode_there_and_time_runs_out_as_truncation():
    env = mdrlat.make("train", max_episode_steps=5)
    x, y, _ = env.reset(seed=0)[1]["pose"]  # a drawn start: free space
    _, info = env.reset(options={"pose": (x, y, 90.0)})
    assert info["pose"] == pytest.approx((x, y, 90.0), abs=1e-4)
    for k in range(5):
        _, _, term, trunc, _ = env.step(9)  # turn on the spot: no collision
    assert (term, trunc) == (False, True)


def test_the_navigation_worlds_add_the_goal():
    env = gym.make("mdrlat/NavTest-v0")
    obs, info = env.reset(seed=0)
    assert env.unwrapped.task == "nav" and obs["goal"].shape == (3,)
    assert "goal" in info
    d, s, c = obs["goal"]
    assert d > 0 and abs(s * s + c * c - 1) < 1e-4


def test_world_files_and_maps_load_by_path():
    env = mdrlat.make(str(REPO / "worlds" / "office.toml"))
    assert env.world_name == "office"
    maps = sorted((REPO.parent / "shared" / "data" / "maps").glob("*.yaml"))
    if maps:
        env = mdrlat.make(str(maps[0]))
        env.reset(seed=0)


def test_an_env_pickles_and_comes_back_the_same():
    env = mdrlat.make("office", max_episode_steps=50)
    again = pickle.loads(pickle.dumps(env))
    assert again.max_episode_steps == 50
    assert same(env.reset(seed=2)[0], again.reset(seed=2)[0])
    again.close()


def test_a_vector_env_pickles_and_comes_back_the_same():
    vec = mdrlat.VectorEnv("office", num_envs=3, max_episode_steps=40)
    vec.reset(seed=5)
    again = pickle.loads(pickle.dumps(vec))  # settings carried; episodes start again
    assert again.num_envs == 3 and again.single.max_episode_steps == 40
    a, b = vec.reset(seed=7)[0], again.reset(seed=7)[0]
    assert all(np.array_equal(a[k], b[k]) for k in a)
    acts = np.array([1, 4, 7])
    ra, rb = vec.step(acts)[1], again.step(acts)[1]
    assert np.array_equal(ra, rb)
    vec.close()
    closed = pickle.loads(pickle.dumps(vec))  # a closed one comes back open
    closed.reset(seed=0)
    again.close()
    closed.close()


def test_bad_input_raises_python_exceptions_naming_it():
    with pytest.raises(ValueError, match="mall"):
        mdrlat.make("mall")
    with pytest.raises(ValueError, match="max_episode_stepz"):
        mdrlat.make("train", max_episode_stepz=3)
    with pytest.raises(ValueError, match="noise_std_m"):
        mdrlat.make("train", laser={"noise_std_m": -1.0})
    with pytest.raises(ValueError, match="depth_memory_frames"):
        mdrlat.make("train", laser={"depth_memory_frames": 65})
    with pytest.raises(ValueError, match="walk"):
        mdrlat.make("train", task="walk")
    with pytest.raises(ValueError, match="goal region"):
        mdrlat.make("office", task="nav")
    env = mdrlat.make("train")
    env.reset(seed=0)
    for bad in (10, -1, 1.5, "3", None, np.array([1, 2])):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    env.step(np.int8(3))  # any integer form is an action
    env.step(np.array([4]))
    with pytest.raises(ValueError, match="pose"):
        env.reset(options={"pose": (1.0, 2.0)})
    with pytest.raises(ValueError, match="only 'pose'"):
        env.reset(options={"goal": (1.0, 2.0)})
    with pytest.raises(ValueError, match="start pose.*not finite"):
        env.reset(options={"pose": (float("nan"), 2.0, 0.0)})
    with pytest.raises(ValueError, match="start pose.*outside the world"):
        env.reset(options={"pose": (1e6, 1e6, 0.0)})
    with pytest.raises(ValueError, match="render_mode"):
        mdrlat.make("train", render_mode="human")


def test_the_vector_env_steps_exactly_as_a_list_of_single_envs():
    n, seed = 3, 11
    vec = gym.make_vec("mdrlat/Crowd-v0", num_envs=n)
    assert isinstance(vec, mdrlat.VectorEnv)
    assert vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    singles = [mdrlat.make("crowd") for _ in range(n)]
    obs, _ = vec.reset(seed=seed)
    assert vec.observation_space.contains({k: v.copy() for k, v in obs.items()})
    expect = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    rng = np.random.default_rng(5)
    ended = 0
    for _ in range(150):
        actions = rng.integers(10, size=n)
        obs, rewards, term, trunc, infos = vec.step(actions)
        assert rewards.dtype == np.float32 and term.dtype == np.bool_
        for i, env in enumerate(singles):
            o, r, te, tr, info = env.step(int(actions[i]))
            assert (rewards[i], term[i], trunc[i]) == (np.float32(r), te, tr)
            if te or tr:
                ended += 1
                assert infos["_final_obs"][i]
                assert same(infos["final_obs"][i], o)
                assert infos["final_info"]["collision"][i] == info["collision"]
                o, _ = env.reset()
            assert all(np.array_equal(obs[k][i], o[k]) for k in o)
    assert ended > 0, "no episode ended: the autoreset path was not tested"
    vec.close()


def test_the_vector_env_takes_actions_in_any_integer_form():
    # int64 arrays go straight to Rust (any shape, strided or not); anything else is
    # converted first. Both must step alike.
    a, b = mdrlat.VectorEnv("train", num_envs=2), mdrlat.VectorEnv("train", num_envs=2)
    a.reset(seed=4)
    b.reset(seed=4)
    rng = np.random.default_rng(2)
    forms = [
        lambda x: [int(v) for v in x],
        lambda x: x.reshape(2, 1),
        lambda x: np.repeat(x, 2)[::2],
        lambda x: x.astype(np.int32),
        tuple,
    ]
    for k in range(20):
        acts = rng.integers(10, size=2)
        oa, ra, *_ = a.step(acts)
        ob, rb, *_ = b.step(forms[k % len(forms)](acts))
        assert np.array_equal(ra, rb) and np.array_equal(oa["depth"], ob["depth"])


def test_the_vector_env_refuses_bad_input():
    vec = mdrlat.VectorEnv("train", num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        vec.step([0, 0])
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="2 environments"):
        vec.step([0, 0, 0])
    with pytest.raises(ValueError, match=r"actions\[1\] = 12"):
        vec.step([0, 12])
    with pytest.raises(ValueError, match="3 seeds"):
        vec.reset(seed=[1, 2, 3])
    for bad in ([0.5, 1.0], ["a", "b"], [None, 1]):
        with pytest.raises(ValueError, match="expected 2 integers"):
            vec.step(bad)
    with pytest.raises(ValueError, match="num_envs 0"):
        mdrlat.VectorEnv("train", num_envs=0)
    with pytest.raises(ValueError, match="num_envs -1"):
        mdrlat.VectorEnv("train", num_envs=-1)
    with pytest.raises(ValueError, match="threads -2"):
        mdrlat.VectorEnv("train", num_envs=2, threads=-2)
    with pytest.raises(ValueError, match="num_envs 2.0"):
        mdrlat.VectorEnv("train", num_envs=2.0)
    with pytest.raises(ValueError, match="num_envs 5000: expected 1 to 4096"):
        mdrlat.VectorEnv("train", num_envs=5000)
    with pytest.raises(ValueError, match="threads 99999999999999999999999"):
        mdrlat.VectorEnv("train", num_envs=2, threads=99999999999999999999999)
    vec.close()
    vec.close()  # twice is harmless
    with pytest.raises(RuntimeError, match="closed"):
        vec.step([0, 0])
    copy.deepcopy(vec)  # copy probes dunder methods: not an error
    with pytest.raises(ValueError, match="mall"):
        mdrlat.VectorEnv("mall", num_envs=2)
    nav = mdrlat.VectorEnv("nav-test", num_envs=2, task="nav")
    obs, _ = nav.reset(seed=0)
    assert obs["goal"].shape == (2, 3) and obs["goal"][:, 0].min() > 0


def test_the_vector_env_reports_final_observations_as_gymnasium_does():
    # `_add_finals` is a one-pass copy of Gymnasium's `VectorEnv._add_info`: same keys,
    # masks, dtypes and values.
    vec = mdrlat.VectorEnv("crowd", num_envs=4)
    vec.reset(seed=3)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(400):
        _, _, term, trunc, infos = vec.step(rng.integers(10, size=4))
        if not (term | trunc).any():
            continue
        expect: dict = {}
        for i in np.flatnonzero(term | trunc):
            info = {k: v[i] for k, v in infos["final_info"].items() if not k.startswith("_")}
            info = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in info.items()}
            expect = vec._add_info(expect, {"final_obs": infos["final_obs"][i], "final_info": info}, i)
        assert sorted(infos) == sorted(["d_min", "_d_min", *expect])
        for key in ("_final_obs", "_final_info"):
            assert np.array_equal(infos[key], expect[key])
        for key, value in expect["final_info"].items():
            got = infos["final_info"][key]
            assert got.dtype == value.dtype, key
            assert all(a == b for a, b in zip(got, value)), key
        assert all((a is None) == (b is None) for a, b in zip(infos["final_obs"], expect["final_obs"]))
        checked += 1
    assert checked > 0, "no episode ended"
    vec.close()


def test_the_scan_with_the_cameras_memory_shows_what_the_laser_misses():
    # furnished's low furniture: driving straight from the same starts, the memory scan
    # reads nearer than the laser's own somewhere, and never farther.
    plain = mdrlat.make("furnished")
    memory = mdrlat.make("furnished", laser={"depth_memory_frames": 8})
    nearer = False
    for seed in range(10):
        a, _ = plain.reset(seed=seed)
        b, _ = memory.reset(seed=seed)
        for _ in range(60):
            assert (b["laser"][-1] <= a["laser"][-1] + 1e-6).all()
            nearer |= bool((b["laser"][-1] < a["laser"][-1] - 0.05).any())
            a, _, end_a, trunc_a, _ = plain.step(1)
            b, _, end_b, trunc_b, _ = memory.step(1)
            assert end_a == end_b and trunc_a == trunc_b, "the same drive"
            if end_a or trunc_a:
                break
    assert nearer
