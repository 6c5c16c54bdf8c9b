"""smg_torch.build_graph: shapes and dtypes, exact KNN on a static scene, the semantic gate,
descriptors from feature samples, the graph feeding the energies, errors."""
import pytest
import torch

import smg_torch as smg


def static_scene(T=4, N=30):
    x0 = torch.randn(N, 3)
    return x0[None].expand(T, N, 3).contiguous(), x0


def test_static_scene_is_euclidean_knn():
    x, x0 = static_scene()
    g = smg.build_graph(x, k=5, gate=False)
    assert g.indices.dtype == torch.int64 and g.indices.shape == (30, 5)
    assert g.weights.shape == (30, 5) and g.distances.shape == (30, 5) and g.features is None
    d = torch.cdist(x0, x0)
    d.fill_diagonal_(float("inf"))
    expect = d.topk(5, largest=False)
    assert torch.equal(g.indices.sort(1).values, expect.indices.sort(1).values)
    assert torch.allclose(g.distances.sort(1).values, expect.values.sort(1).values, atol=1e-12)
    assert torch.allclose(g.weights.sum(1), torch.ones(30))  # uniform: 1/|N(i)|


def test_gate_and_feature_samples():
    x, x0 = static_scene(N=40)
    group = (x0[:, 0] > 0).long()
    f = torch.nn.functional.one_hot(group, 2).double()
    g = smg.build_graph(x, features=f, k=6, tau=0.5, isolated="leave")
    valid = g.indices >= 0
    same = group[g.indices.clamp(min=0)] == group[:, None]
    assert bool(same[valid].all())
    assert torch.equal(g.features, f)
    # descriptors from per-frame samples (constant over time: the descriptor is the feature)
    fs = f[None].expand(4, 40, 2).contiguous()
    g2 = smg.build_graph(x, feature_samples=fs, k=6, tau=0.5, isolated="leave")
    assert g2.features.shape == (40, 2)
    assert torch.equal(g2.indices, g.indices)
    # the int64 graph drives the energies directly
    q = torch.randn(4, 40, 4)
    e = smg.carap(x + 0.01 * torch.randn_like(x), q, g, smg.node_confidences(x, g))
    assert torch.isfinite(e)


def test_float32_and_visibility():
    x, _ = static_scene()
    vis = torch.ones(4, 30, dtype=torch.bool)
    vis[0, :5] = False
    g32 = smg.build_graph(x.float(), vis, k=4, weighting="distance", gate=False)
    g64 = smg.build_graph(x, vis, k=4, weighting="distance", gate=False)
    assert g32.weights.dtype == torch.float32
    assert torch.equal(g32.indices, g64.indices)


@pytest.mark.parametrize("kw", [dict(k=0), dict(aggregation="median"), dict(isolated="drop"),
                                dict(weighting="cosine"), dict(rho=0.0), dict(m=0),
                                dict(features=torch.ones(7, 2)), dict(visibility=torch.ones(4, 3))])
def test_graph_errors(kw):
    x, _ = static_scene()
    with pytest.raises(ValueError):
        smg.build_graph(x, **kw)
