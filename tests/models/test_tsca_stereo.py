import numpy as np
import pytest
import torch

from spacepose.errors import ShapeError
from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_loss import sequence_loss
from spacepose.models.tsca_stereo import TSCAStereo


def _random_dot_pair(seed: int, size: int = 64, d0: int = 6, slope: float = 0.0):
    """Left/right (1, 3, size, size) in [0, 255] and GT (1, 1, size, size): row y has disparity
    round(d0 + slope * y); left(x) = right(x - d)."""
    rng = np.random.default_rng(seed)
    pad = 32
    tex = (rng.random((size, size + pad)) > 0.5).astype(np.float32) * 255.0
    tex = np.repeat(np.repeat(tex[:, ::2], 2, axis=1), 1, axis=0)[:, : size + pad]  # 2-px dots along x
    left = np.empty((size, size), np.float32)
    right = np.empty((size, size), np.float32)
    disp = np.empty((size, size), np.float32)
    for y in range(size):
        d = int(round(d0 + slope * y))
        right[y] = tex[y, pad : pad + size]
        left[y] = tex[y, pad - d : pad - d + size]  # left(x) = tex(x - d + pad) = right(x - d)
        disp[y] = d
    to_t = lambda a: torch.from_numpy(a)[None, None].repeat(1, 3, 1, 1)  # noqa: E731
    return to_t(left), to_t(right), torch.from_numpy(disp)[None, None]


def _small_cfg(variant: str = "full") -> StereoConfig:
    return StereoConfig.cpu(variant).replace(max_disp=32, train_iters=2, iters=2)


def test_train_and_test_mode_shapes():
    torch.manual_seed(0)
    model = TSCAStereo(_small_cfg())
    x = torch.rand(2, 3, 64, 96) * 255
    init, preds = model(x, x)
    assert init.shape == (2, 1, 64, 96) and len(preds) == 2 and all(p.shape == (2, 1, 64, 96) for p in preds)
    model.eval()
    with torch.no_grad():
        assert model(x, x, iters=3, test_mode=True).shape == (2, 1, 64, 96)
        assert model(x, x, iters=0, test_mode=True).shape == (2, 1, 64, 96)


def test_bad_inputs_raise():
    model = TSCAStereo(_small_cfg())
    with pytest.raises(ShapeError, match="multiples of 32"):
        model(torch.zeros(1, 3, 60, 64), torch.zeros(1, 3, 60, 64))
    with pytest.raises(ShapeError):
        model(torch.zeros(1, 3, 64, 64), torch.zeros(1, 3, 64, 96))
    with pytest.raises(ValueError):
        model(torch.zeros(1, 3, 64, 64), torch.zeros(1, 3, 64, 64), iters=0)


def test_variants_differ_in_structure():
    names = {v: {type(m).__name__ for m in TSCAStereo(StereoConfig.cpu(v)).modules()} for v in ("igev", "ta", "seca", "full")}
    assert "TripletAttention" not in names["igev"] and "SECA" not in names["igev"]
    assert "TripletAttention" in names["ta"] and "SECA" not in names["ta"]
    assert "TripletAttention" not in names["seca"] and "SECA" in names["seca"]
    assert {"TripletAttention", "SECA"} <= names["full"]


def test_cpu_model_size():
    n = sum(p.numel() for p in TSCAStereo(StereoConfig.cpu()).parameters())
    assert 0.5e6 <= n <= 1.5e6


def _tiny_cfg() -> StereoConfig:
    """Narrow "full" model (~0.2 M params) so the overfit test stays within seconds."""
    return _small_cfg().replace(
        feature_widths=(8, 16, 16, 16, 16), match_dim=16, groups=4, context_widths=(16, 16, 16),
        hidden_dims=(16, 16), motion_dim=16, reg_widths=(8, 8, 16, 16),
    )


@pytest.mark.slow
def test_overfits_two_random_dot_pairs():
    torch.manual_seed(0)
    cfg = _tiny_cfg()
    model = TSCAStereo(cfg)
    pairs = [_random_dot_pair(1, d0=5.0), _random_dot_pair(2, d0=3.0, slope=0.12)]
    left = torch.cat([p[0] for p in pairs])
    right = torch.cat([p[1] for p in pairs])
    gt = torch.cat([p[2] for p in pairs])
    valid = torch.ones_like(gt, dtype=torch.bool)
    valid[..., :16] = False  # left border: no match in the right image
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    losses = []
    for _ in range(20):
        init, preds = model(left, right)
        loss, _ = sequence_loss(init, preds, gt, valid, cfg.max_disp)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-3:]) < 0.4 * np.mean(losses[:3]), losses  # ~17 -> ~1.3 in practice


def test_onnx_export_matches_torch(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    torch.manual_seed(0)
    model = TSCAStereo(StereoConfig.cpu().replace(max_disp=32)).eval()

    class Fixed(torch.nn.Module):
        def __init__(self, net):
            super().__init__()
            self.net = net

        def forward(self, left, right):
            return self.net(left, right, iters=2, test_mode=True)

    left, right, _ = _random_dot_pair(3, d0=4.0)
    path = tmp_path / "stereo.onnx"
    with torch.no_grad():
        expected = Fixed(model)(left, right).numpy()
        torch.onnx.export(
            Fixed(model), (left, right), str(path), input_names=["left", "right"], output_names=["disparity"],
            opset_version=17, dynamo=False,
        )
    import onnx

    ops = {node.op_type for node in onnx.load(str(path)).graph.node}
    assert not ops & {"GridSample", "ScatterND", "Unique"}, ops
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    got = sess.run(None, {"left": left.numpy(), "right": right.numpy()})[0]
    np.testing.assert_allclose(got, expected, atol=1e-3, rtol=0)
