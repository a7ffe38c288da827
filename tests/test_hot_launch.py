"""Split launches handed to spinning workers while steps run (launch.hot): the same results as the
sleeping pool, workers parked between runs, errors raised on the launching thread, and other
threads' launches left to the pool.  conftest.py turns the workers off for the other tests."""

import hashlib
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from warp_sim import FourierTerrain, cases
from warp_sim import launch as launching

pytestmark = pytest.mark.skipif(launching._spin_library() is None, reason="libc without pthread spinlocks")


@wp.kernel
def doubled(tid_offset: int, out: wp.array(dtype=int)):
    i = wp.tid() + tid_offset
    out[i] = 2 * i


def rain_digest() -> str:
    sim = cases.terrain_drop(120, "mix", terrain=FourierTerrain(amplitude=0.4), body_contact=True, spacing=0.6,
                             restitution=0.3, pair_schedule="domains")
    sim.step(40)
    h = hashlib.sha256()
    for a in sim.state.fields():
        h.update(np.ascontiguousarray(a.numpy()).tobytes())
    return h.hexdigest()


@pytest.fixture
def two_threads(monkeypatch):
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "2")


def test_steps_with_spinning_workers_equal_the_pool(two_threads, monkeypatch):
    """The slab sweeps split into two chunks whatever the scene's size (min_chunk 1): each chunk a
    launch of its own, so who runs it changes no bit."""
    runs = []
    real_run = launching._HotWorkers.run

    def counted(self, jobs):
        runs.append(len(jobs))
        return real_run(self, jobs)

    monkeypatch.setattr(launching._HotWorkers, "run", counted)
    monkeypatch.setenv("WARP_SIM_HOT", "0")
    pool = rain_digest()
    assert not runs
    monkeypatch.setenv("WARP_SIM_HOT", "1")
    assert rain_digest() == pool
    assert runs and set(runs) == {2}
    assert launching._hot is None and launching._hot_owner is None


def thread_cpu_ticks(native_id: int) -> int:
    fields = Path(f"/proc/self/task/{native_id}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])  # utime + stime


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_are_parked_between_runs_and_use_no_cpu(two_threads, monkeypatch):
    monkeypatch.setenv("WARP_SIM_HOT", "1")
    out = wp.zeros(16, dtype=int, device="cpu")
    launching.launch(doubled, 16, [out], "cpu", min_chunk=1)  # loads the module, whole
    with launching.hot():
        launching.launch(doubled, 16, [out], "cpu", min_chunk=1)
    assert np.array_equal(out.numpy(), 2 * np.arange(16))
    workers = [t for t in threading.enumerate() if t.name == "warp_sim_hot"]
    assert workers
    before = [thread_cpu_ticks(t.native_id) for t in workers]
    time.sleep(0.5)  # a spinning thread would take ~50 ticks of 10 ms here
    after = [thread_cpu_ticks(t.native_id) for t in workers]
    assert all(b - a <= 2 for a, b in zip(before, after)), (before, after)


def test_an_error_in_a_workers_chunk_is_raised_on_the_launching_thread(two_threads, monkeypatch):
    monkeypatch.setenv("WARP_SIM_HOT", "1")
    ran = []

    def fail():
        raise RuntimeError("chunk 1 failed")

    with launching.hot():
        with pytest.raises(RuntimeError, match="chunk 1 failed"):
            launching._hot.run([(ran.append, (0,), {}), (fail, (), {})])
        launching._hot.run([(ran.append, (1,), {}), (ran.append, (2,), {})])  # the handshake still holds
    assert sorted(ran) == [0, 1, 2]


def test_other_threads_launch_through_the_pool_meanwhile(two_threads, monkeypatch):
    monkeypatch.setenv("WARP_SIM_HOT", "1")
    out = wp.zeros(64, dtype=int, device="cpu")
    launching.launch(doubled, 64, [out], "cpu", min_chunk=1)
    other = wp.zeros(64, dtype=int, device="cpu")
    errors = []

    def elsewhere():
        try:
            with launching.hot():  # not the owner: a no-op
                for _ in range(20):
                    launching.launch(doubled, 64, [other], "cpu", min_chunk=1)
        except Exception as error:  # noqa: BLE001
            errors.append(error)

    with launching.hot(), launching.hot():  # nests
        thread = threading.Thread(target=elsewhere)
        thread.start()
        for _ in range(20):
            launching.launch(doubled, 64, [out], "cpu", min_chunk=1)
        thread.join()
        assert launching._hot is not None
    assert not errors
    assert launching._hot is None
    assert np.array_equal(out.numpy(), 2 * np.arange(64)) and np.array_equal(other.numpy(), 2 * np.arange(64))
