"""Time travel: keyframes plus deterministic re-simulation.

The timeline is the run from step 0 to ``head``.  Every ``interval`` steps a keyframe
(``Simulator.snapshot()``) is kept; reaching any step means restoring the nearest keyframe at or
before it and re-simulating, which on CPU reproduces the original states bit for bit.  Stepping
backwards re-simulates one keyframe interval once and keeps each of its steps in a small dense
cache, so holding the left arrow costs one restore per frame.

Parameters may change at any step.  Each change starts an *epoch* (the step and the settings in
force from it on: SimConfig fields and the terrain); re-simulation switches settings at the epoch
boundaries exactly as the live run did.  Changing a parameter at a past step forks the timeline:
everything after the current step is dropped (the future under the old parameters is gone).

Memory: keyframes count against ``memory_budget`` bytes; when it is exceeded the interval doubles
and every other keyframe is dropped, so a long run keeps a bounded, evenly spaced set.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, fields


@dataclass
class Epoch:
    step: int
    config: dict  # SimConfig field values in force from ``step`` on
    terrain: object


def snapshot_bytes(snapshot: dict) -> int:
    return sum(a.capacity for a in snapshot["arrays"])


def config_values(config) -> dict:
    return {f.name: getattr(config, f.name) for f in fields(config) if f.name != "extra"}


class History:
    def __init__(self, sim, interval: int = 32, memory_budget: int = 256 << 20, cache_steps: bool = True):
        if interval < 1:
            raise ValueError(f"history interval must be >= 1, got {interval}")
        self.sim = sim
        self.base_interval = int(interval)
        self.memory_budget = int(memory_budget)
        self.cache_steps = cache_steps
        self.clear()

    # Bookkeeping ------------------------------------------------------------------------------

    def clear(self):
        """Start a new timeline at the simulator's current step (after a reset or rebuild)."""
        self.interval = self.base_interval
        self.keyframes: dict[int, dict] = {}
        self.dense: dict[int, dict] = {}
        self.epochs: list[Epoch] = []
        self.head = self.sim.step_count
        self.origin = self.sim.step_count
        self._store_keyframe()
        self.epochs.append(self._current_epoch(self.origin))

    @property
    def current(self) -> int:
        return self.sim.step_count

    def _current_epoch(self, step: int) -> Epoch:
        return Epoch(step, config_values(self.sim.config), self.sim.model.terrain)

    def keyframe_bytes(self) -> int:
        return sum(snapshot_bytes(s) for s in self.keyframes.values())

    def _store_keyframe(self):
        step = self.current
        if step not in self.keyframes:
            self.keyframes[step] = self.sim.snapshot()
            self._enforce_budget()

    def _enforce_budget(self):
        while len(self.keyframes) > 2 and self.keyframe_bytes() > self.memory_budget:
            self.interval *= 2
            keep = {s: v for s, v in self.keyframes.items()
                    if s == self.origin or (s - self.origin) % self.interval == 0 or s == self.current}
            if len(keep) == len(self.keyframes):
                break
            self.keyframes = keep

    def epoch_at(self, step: int) -> Epoch:
        starts = [e.step for e in self.epochs]
        return self.epochs[max(bisect.bisect_right(starts, step) - 1, 0)]

    def _apply_epoch(self, epoch: Epoch) -> bool:
        """Make the simulator's settings those of ``epoch``; True if anything changed."""
        changed = False
        current = config_values(self.sim.config)
        diff = {k: v for k, v in epoch.config.items() if current.get(k) != v}
        if diff:
            self.sim.update_settings(**diff)
            changed = True
        if self.sim.model.terrain is not epoch.terrain:
            self.sim.set_terrain(epoch.terrain)
            changed = True
        return changed

    # Moving along the timeline ----------------------------------------------------------------

    def step_forward(self, count: int = 1):
        """Simulate ``count`` steps; beyond ``head`` this extends the timeline."""
        for _ in range(count):
            self._apply_epoch(self.epoch_at(self.current))
            self.sim.step()
            self.head = max(self.head, self.current)
            if (self.current - self.origin) % self.interval == 0:
                self._store_keyframe()

    def step_backward(self, count: int = 1):
        self.seek(self.current - count)

    def seek(self, target: int):
        """Go to any step in [origin, head]; returns the step reached."""
        target = int(min(max(target, self.origin), self.head))
        if target == self.current:
            return target
        if target in self.dense:
            self._restore(target, self.dense[target])
            return target
        if self.current < target <= self.current + self.interval:
            self.step_forward(target - self.current)
            return target
        start = max(s for s in self.keyframes if s <= target)
        self._restore(start, self.keyframes[start])
        backwards = target < self.head
        if self.cache_steps and backwards:
            self.dense = {start: self.keyframes[start]}
        while self.current < target:
            self.step_forward(1)
            if self.cache_steps and backwards:
                self.dense[self.current] = self.sim.snapshot()
        return target

    def _restore(self, step: int, snapshot: dict):
        self._apply_epoch(self.epoch_at(step))
        self.sim.restore(snapshot)

    # Editing ----------------------------------------------------------------------------------

    def fork(self):
        """Drop everything after the current step: call before changing a parameter."""
        step = self.current
        self.keyframes = {s: v for s, v in self.keyframes.items() if s <= step}
        self.dense = {}
        self.epochs = [e for e in self.epochs if e.step <= step]
        self.head = step
        self._store_keyframe()

    def record_settings(self):
        """Record the simulator's current settings as in force from the current step on."""
        epoch = self._current_epoch(self.current)
        if self.epochs and self.epochs[-1].step == epoch.step:
            self.epochs[-1] = epoch
        else:
            self.epochs.append(epoch)
        self.dense = {}
