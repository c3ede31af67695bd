"""The PyTorch networks give the Rust networks' Q-values (skipped without torch, unless
MDRLAT_REQUIRE_TORCH=1 says torch must be there, as in CI)."""

import os
from pathlib import Path

import numpy as np
import pytest

if os.environ.get("MDRLAT_REQUIRE_TORCH") == "1":
    import torch  # a missing torch fails the run instead of skipping it
else:
    torch = pytest.importorskip("torch")
from mdrlat.qnet import QNet, read_safetensors  # noqa: E402

REFERENCES = os.environ.get("MDRLAT_QNET_REFERENCES")
REPO = Path(__file__).resolve().parents[2]


def cases():
    if not REFERENCES or not Path(REFERENCES).is_dir():
        return []
    return sorted(p for p in Path(REFERENCES).iterdir() if (p / "q.npy").is_file())


def test_the_reference_networks_are_there_when_torch_is_required():
    if os.environ.get("MDRLAT_REQUIRE_TORCH") == "1":
        assert cases(), f"MDRLAT_REQUIRE_TORCH=1 but no reference networks in {REFERENCES!r}"


@pytest.mark.skipif(not cases(), reason="no reference networks (run through cargo test -p mdrlat-py)")
@pytest.mark.parametrize("case", cases(), ids=lambda p: p.name)
def test_the_torch_network_gives_the_rust_q_values(case):
    net = QNet.load(case)
    inputs = {k: np.load(case / f"{k}.npy") for k in ("laser", "depth", "goal")}
    if not net.goal_dim:
        inputs.pop("goal")
    with torch.no_grad():
        q = net(**inputs).numpy()
    expect = np.load(case / "q.npy")
    assert q.shape == expect.shape == (5, 10)
    err = np.abs(q - expect).max()
    assert err <= 1e-4 * max(1.0, np.abs(expect).max()), f"{case.name}: max |ΔQ| {err}"
    assert (net.greedy(**inputs) == expect.argmax(axis=1)).all()


def test_a_shipped_f16_model_loads_and_decides():
    model = REPO / "models" / "laser-only-cpu-small"
    net = QNet.load(model)
    assert net.variant == "laser-only" and net.goal_dim == 0
    q = net(laser=np.full((2, 4, 512), 3.0, np.float32))
    assert q.shape == (2, 10) and torch.isfinite(q).all()
    nav = QNet.load(REPO / "models" / "laser-only-nav")
    assert nav.goal_dim == 3
    with pytest.raises(ValueError, match="goal"):
        nav(laser=np.full((1, 4, 512), 3.0, np.float32))
    with pytest.raises(ValueError, match="not an mdrlat model|safetensors"):
        QNet.load(REPO / "python" / "README.md")
    _, meta = read_safetensors(model / "model.safetensors")
    assert meta["mdrlat_variant"] == "laser-only"
