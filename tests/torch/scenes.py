"""Small scenes for tests/torch: positions [T, N, 3], raw quaternions [T, N, 4], a kNN graph
(indices int64 [N, K], -1 padded, weights) with padding and an empty row, confidences."""
import torch


def knn_graph(x0, k, pad_rows=(1,), empty_rows=(), dtype=torch.float64):
    N = x0.shape[0]
    d = torch.cdist(x0, x0)
    d.fill_diagonal_(float("inf"))
    idx = d.topk(k, largest=False).indices
    w = torch.rand(N, k, dtype=dtype) + 0.1
    for i in pad_rows:  # the last two entries of row i are padding
        idx[i, k - 2:] = -1
        w[i, k - 2:] = 0
    for i in empty_rows:
        idx[i, :] = -1
        w[i, :] = 0
    return idx, w


def random_scene(T=7, N=12, K=4, dtype=torch.float64, motion=0.05, empty_rows=(5,)):
    x0 = torch.randn(N, 3, dtype=dtype)
    x = x0[None] + motion * torch.randn(T, N, 3, dtype=dtype).cumsum(0)
    q = torch.randn(T, N, 4, dtype=dtype)
    idx, w = knn_graph(x0, K, empty_rows=empty_rows, dtype=dtype)
    c = torch.rand(T, N, dtype=dtype)
    return x, q, idx, w, c


def antipodal(q):
    """Every other frame and node flipped to -q (same rotation)."""
    q = q.clone()
    q[1::2] = -q[1::2]
    q[:, ::3] = -q[:, ::3]
    return q


def coincident(x, idx):
    """Node 0's first neighbour sits on node 0 in every frame (zero-length edge)."""
    x = x.clone()
    x[:, int(idx[0, 0])] = x[:, 0]
    return x


def collinear(T=6, N=9, K=4, dtype=torch.float64):
    """All nodes on one line (moving along and across it); every neighbourhood collinear."""
    s = torch.linspace(-1, 1, N, dtype=dtype)
    direction = torch.tensor([1.0, 2.0, -0.5], dtype=dtype)
    direction = direction / direction.norm()
    x0 = s[:, None] * direction
    shift = 0.03 * torch.randn(T, 1, 3, dtype=dtype).cumsum(0)
    x = x0[None] + shift + 0.01 * torch.arange(T, dtype=dtype)[:, None, None] * s[None, :, None] * direction
    q = torch.randn(T, N, 4, dtype=dtype)
    idx, w = knn_graph(x0, K, pad_rows=(), dtype=dtype)
    return x, q, idx, w
