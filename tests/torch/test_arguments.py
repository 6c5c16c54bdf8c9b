"""smg_torch's hostile arguments (issue 22): messages name the Python argument (quats, not the
library's rotations), every integer argument is range-checked before it is narrowed, and large
outputs are estimated against the memory limit (smg_torch.set_memory_limit) before allocation."""
import os

import pytest
import torch

import smg_torch as smg
from scenes import random_scene
from test_render import small_scene
from test_skin import skin_scene

GiB = 2 ** 30


@pytest.fixture
def restore_limit():
    limit = smg.memory_limit()
    yield
    smg.set_memory_limit(limit)


def raises_naming(name, f, *needles):
    with pytest.raises(ValueError) as info:
        f()
    msg = str(info.value)
    assert msg.startswith(name + ":") or msg.startswith(name + "["), msg
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, msg
    return msg


# quats: every operator that takes quaternions names them as its Python argument.
def test_messages_name_quats():
    x, q, idx, w, c = random_scene()
    g = (idx, w)
    bad = {"shape": q[:, :5], "dtype": q.float(), "nan": q.clone().index_fill_(1, torch.tensor([3]), float("nan")),
           "zero": q.clone().index_fill_(1, torch.tensor([2]), 0.0)}
    for what, qb in bad.items():
        for op in (lambda: smg.carap(x, qb, g, c), lambda: smg.arap(x, qb, g),
                   lambda: smg._library_seconds("carap", x, qb, g, c, repeat=1)):
            msg = raises_naming("quats", op)
            assert "rotations" not in msg, (what, msg)


# Every integer argument: each hostile value is a ValueError naming the argument (never a
# wrap-around: tile_size = 2**32 + 16 would be 16 as an int).
HOSTILE = (-1, 0, -2 ** 31, 2 ** 31, 2 ** 32 + 16, 2 ** 63, -2 ** 63 - 1, 2 ** 64 + 8, 10 ** 30)


def _int_calls():
    x, q, idx, w, c = random_scene()
    g = (idx, w)
    t, W, H = small_scene()

    def render(**kw):
        a = dict(width=W, height=H)
        a.update(kw)
        w_, h_ = a.pop("width"), a.pop("height")
        return smg.render(t["means"], t["quats"], t["scales"], t["opacities"], t["colors"],
                          t["viewmat"], t["K"], w_, h_, **a)

    return {
        "k": (lambda v: smg.build_graph(x, k=v), (1, 1 << 20)),
        "m": (lambda v: smg.build_graph(x, m=v), (1, 2 ** 31 - 1)),
        "min_covisible": (lambda v: smg.build_graph(x, min_covisible=v), (0, 2 ** 31 - 1)),
        "gaps[1]": (lambda v: smg.carap(x, q, g, c, gaps=(1, v)), (1, 10 ** 6)),
        "gaps[0]": (lambda v: smg.arap(x, q, g, gaps=(v,)), (1, 10 ** 6)),
        "width": (lambda v: render(width=v), (1, 65536)),
        "height": (lambda v: render(height=v), (1, 65536)),
        "tile_size": (lambda v: render(tile_size=v), (8, 32)),
        "repeat": (lambda v: smg._library_seconds("lrm", x, None, g, c, repeat=v), (1, 10 ** 6)),
    }


@pytest.mark.parametrize("name", list(_int_calls()))
def test_integer_arguments_are_range_checked(name):
    call, (lo, hi) = _int_calls()[name]
    for v in HOSTILE:
        if lo <= v <= hi:
            continue
        raises_naming(name, lambda: call(v))


def test_tile_size_does_not_wrap():
    t, W, H = small_scene()
    args = (t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], t["viewmat"], t["K"], W, H)
    ref = smg.render(*args, tile_size=16)[0]
    for v in (2 ** 32 + 16, 2 ** 64 + 16, -(2 ** 32) + 16):
        raises_naming("tile_size", lambda: smg.render(*args, tile_size=v))
    raises_naming("tile_size", lambda: smg.render(*args, tile_size=12), "8, 16 or 32")
    assert torch.equal(smg.render(*args, tile_size=16)[0], ref)


# The memory limit: a huge request is refused before anything large is allocated, naming the
# argument and giving the estimate.
def _dqb(scene, t_query):
    x, q, idx, w, pts, pq, anchor, t_ref, _, sigma = scene
    return smg.dqb(x, q, (idx, w), pts, pq, anchor, t_ref, t_query, sigma)


def test_huge_dqb_is_refused_with_an_estimate():
    assert smg.memory_limit() == 8 * GiB or "SMG_TORCH_MAX_MEMORY_GB" in os.environ
    scene = skin_scene(P=16)
    t_query = torch.zeros(1, dtype=torch.int64).expand(2 ** 26)  # stride 0: nothing allocated
    msg = raises_naming("t_query", lambda: _dqb(scene, t_query), "needs about", "GiB",
                        "set_memory_limit", "Q = 67108864")
    assert "56 GiB" in msg  # 2^26 x 16 points x 7 doubles


def test_huge_render_is_refused_with_an_estimate():
    t, _, _ = small_scene()
    args = (t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], t["viewmat"], t["K"])
    raises_naming("width, height", lambda: smg.render(*args, 65536, 65536), "65536x65536",
                  "needs about", "GiB", "set_memory_limit")
    raises_naming("width", lambda: smg.render(*args, 65537, 16))


def test_huge_graph_is_refused_with_an_estimate():
    x = torch.randn(2, 4096, 3)
    raises_naming("k", lambda: smg.build_graph(x, k=1 << 20), "needs about", "set_memory_limit")


def test_memory_limit_override(restore_limit):
    scene = skin_scene(P=16)
    t_query = torch.zeros(64, dtype=torch.int64)  # 64 x 16 x 7 doubles = 56 KiB of outputs
    _dqb(scene, t_query)
    smg.set_memory_limit(16 * 1024)
    assert smg.memory_limit() == 16 * 1024
    raises_naming("t_query", lambda: _dqb(scene, t_query), "needs about", "Q = 64")
    t, W, H = small_scene()
    raises_naming("width, height", lambda: smg.render(t["means"], t["quats"], t["scales"], t["opacities"],
                                                       t["colors"], t["viewmat"], t["K"], 128, 128))
    smg.set_memory_limit(1 * GiB)
    px, pq = _dqb(scene, t_query)
    assert px.shape == (64, 16, 3) and pq.shape == (64, 16, 4)
    for bad in (0, -1, float("nan"), float("inf"), 2.0 ** 51):
        with pytest.raises(ValueError, match="set_memory_limit"):
            smg.set_memory_limit(bad)
    assert smg.memory_limit() == 1 * GiB


@pytest.mark.skipif(open("/proc/sys/vm/overcommit_memory").read().strip() == "1"
                    if os.path.exists("/proc/sys/vm/overcommit_memory") else True,
                    reason="needs an allocator that refuses a 4 TiB request")
def test_allocation_failure_is_a_value_error(restore_limit):
    """Above the estimate's reach (limit raised to 2^50 bytes): the allocator's failure becomes a
    ValueError naming the argument. 2^20 nodes x k = 2^20 int32 indices = 4 TiB."""
    smg.set_memory_limit(2.0 ** 50)
    x = torch.zeros(1, 1 << 20, 3)
    raises_naming("k", lambda: smg.build_graph(x, k=1 << 20), "out of memory")


def test_render_messages_name_arguments():
    t, W, H = small_scene()
    args = (t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], t["viewmat"], t["K"], W, H)
    raises_naming("radius_sigmas", lambda: smg.render(*args, radius_sigmas=0))
    raises_naming("alpha_max", lambda: smg.render(*args, alpha_max=1.5))
    raises_naming("eps2d", lambda: smg.render(*args, eps2d=-1))
    raises_naming("near", lambda: smg.render(*args, near=-1))
    raises_naming("far", lambda: smg.render(*args, near=1, far=0.5))
