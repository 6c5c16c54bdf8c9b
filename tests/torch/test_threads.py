# smg's parallel loops inside a torch process run on torch's intra-op threads, as many as
# torch.set_num_threads says (issue 24: with Debian's torch, OpenMP backend, an extension
# compiled without -fopenmp ran every at::parallel_for on one thread). The loop under test is
# smg_torch._C._parallel_threads: its chunks meet at a rendezvous (each waits until `wanted`
# distinct threads have run a chunk, or a timeout), so the count of distinct threads it returns
# does not depend on how the OS schedules the threads; no timing is asserted.
import pytest
import torch

import smg_torch as smg

# Generous: the rendezvous normally completes in microseconds; the timeout only bounds a failure.
MEET_SECONDS = 5.0


@pytest.fixture
def torch_threads():
    before = torch.get_num_threads()
    yield torch.set_num_threads
    torch.set_num_threads(before)


@pytest.mark.parametrize("threads", [2, 3])
def test_chunks_run_on_every_torch_thread(torch_threads, threads):
    torch_threads(threads)
    assert smg._C._parallel_threads(8, threads, MEET_SECONDS) == threads


def test_chunks_run_on_one_thread_when_torch_uses_one(torch_threads):
    torch_threads(1)
    # Nobody can join: the first chunk waits out the (short) timeout, then all run on this thread.
    assert smg._C._parallel_threads(8, 2, 0.05) == 1


def test_no_more_threads_than_torch_uses(torch_threads):
    torch_threads(2)
    # Asks for a third participant that torch's count does not allow: two threads, after the timeout.
    assert smg._C._parallel_threads(8, 3, 0.5) == 2


def test_arguments_are_checked():
    with pytest.raises(ValueError, match="chunks"):
        smg._C._parallel_threads(0, 2, 1.0)
    with pytest.raises(ValueError, match="timeout_seconds"):
        smg._C._parallel_threads(4, 2, 0.0)
