"""Graph colouring of body-body contact pairs, so Gauss-Seidel can run in parallel.

Two pairs that share a dynamic body must not be solved at the same time (both would write that
body's velocity).  Pairs of one colour share no dynamic body, so a colour is one parallel
launch; colours run one after another, which keeps the sweep Gauss-Seidel.  Static (and
sleeping) bodies take no colour: any number of pairs may touch the ground at once.

The colouring is Jones-Plassmann with first-fit colours, in parallel rounds of three launches:

* claim: every uncoloured pair writes its priority into both of its dynamic bodies with an
  atomic max and an atomic min (neither result depends on the order of the writers);
* pick the maxima: a pair that holds the maximum at each of its dynamic bodies is a local
  maximum among the uncoloured pairs around it, so no other pair touching its bodies is picked
  with it; it takes the lowest colour neither body uses yet (a bit mask per body) and writes
  those two masks alone;
* pick the minima the same way, in a launch of their own, so that they see the colours the
  maxima just took (a body may gain two colours a round, which halves the rounds).

Priorities are a hash of the pair (i, j) (the pair index breaks hash ties, so no two pairs are
equal), and the round number sits in the high bits (rising for the max, falling for the min),
so a body's extremes from an earlier round never need clearing.  The result depends only on the pair list, not on thread order: the same
colours on every run, device and CPU thread count.  The pairs are then radix-sorted by colour
(stable, so in pair order within a colour) and the colour starts found by one thread per sorted
entry at the colour boundaries: no counter is shared.

A pair left uncoloured after ROUND_CAP rounds, or whose bodies already use all COLOR_COUNT
colours between them, goes to the overflow set, the last bucket: the last resort, which the
solver sweeps with split masses on CUDA and walks in order on the CPU (solvers/pair_overflow.py).
``overflow`` flags it on the device; Simulator.step reads the flag once per call, after its steps.  Measured on a 10x10x10 lattice of
touching cubes (10,476 pairs, about 21 a body, the densest case the tests build): 44 rounds and
33 colours, none left over (93 rounds with the maxima alone); the greedy sequential walk this
replaced needed more than its 24 colours (5.6 % of the pairs went to its one-thread overflow).
A body gains at most two colours a round, so the rounds grow with the pairs a body has;
colouring from per-body adjacency lists (speculative colours, conflicts settled per body)
would colour several at once and is the next step if the rounds cost too much on a GPU.

The rounds run in a loop that stops once no pair is pending: ``wp.capture_while`` on a device
flag, which a captured step records as a conditional while node and direct stepping runs as a
loop reading the flag (captured steps used to run all ROUND_CAP rounds, the idle ones returning
at once: on an H200 most of the colouring's time at 1M bodies).  Each launch is capacity-sized
when the pipeline is captured (threads past the live pair count return at once); direct CPU
stepping sizes them from the live count.
"""

import warp as wp

from ..launch import LIGHT_CHUNK, gpu_blocks, launch

wp.set_module_options({"enable_backward": False})

COLOR_COUNT = 40  # colours in the int64 masks; the last bucket (index COLOR_COUNT) is the overflow set
ROUND_CAP = 96  # Jones-Plassmann rounds; a 10x10x10 lattice of touching cubes needs 44
NO_POINTS = -1  # a candidate pair without contact points takes no colour
UNCOLORED = -2
LEAST_EMPTY = 0x7FFFFFFFFFFFFFFF  # no pair at the body this round (atomic min)
SORT_BITS = 6  # keys are colours 0 .. COLOR_COUNT + 1 (the last: no points / past the live count)


@wp.func
def pair_hash(i: int, j: int, p: int) -> wp.int64:
    h = wp.uint32(i) * wp.uint32(0x9E3779B1) ^ (wp.uint32(j) * wp.uint32(0x85EBCA77) + wp.uint32(0x165667B1))
    h = h ^ (h >> wp.uint32(15))
    h = h * wp.uint32(0x2C1B3C6D)
    h = h ^ (h >> wp.uint32(12))
    h = h * wp.uint32(0x297A2D39)
    h = h ^ (h >> wp.uint32(15))
    return (wp.int64(h & wp.uint32(0xFFFF)) << wp.int64(32)) | wp.int64(p)


@wp.func
def pair_priority(i: int, j: int, p: int, round: int) -> wp.int64:
    """Key of the atomic max: later rounds above earlier ones, so no clearing between rounds."""
    return (wp.int64(round) << wp.int64(48)) | pair_hash(i, j, p)


@wp.func
def pair_priority_low(i: int, j: int, p: int, round: int) -> wp.int64:
    """Key of the atomic min: later rounds below earlier ones."""
    return (wp.int64(ROUND_CAP - round) << wp.int64(48)) | pair_hash(i, j, p)


@wp.kernel
def color_init(
    tid_offset: int,
    pair_count: wp.array(dtype=wp.int32),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_color: wp.array(dtype=wp.int32),
    pending: wp.array(dtype=wp.int32),
):
    p = wp.tid() + tid_offset
    if p == 0:
        pending[0] = 1
    if p >= pair_count[0]:
        return
    if pair_point_count[p] > 0:
        pair_color[p] = UNCOLORED
    else:
        pair_color[p] = NO_POINTS


@wp.kernel
def color_claim(
    round_index: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_color: wp.array(dtype=wp.int32),
    pending: wp.array(dtype=wp.int32),
    # atomic max and min, order-independent
    body_best: wp.array(dtype=wp.int64),
    body_least: wp.array(dtype=wp.int64),
):
    p = wp.tid()
    round = round_index[0]
    if pending[round] == 0 or p >= pair_count[0] or pair_color[p] != UNCOLORED:
        return
    ij = pair_body[p]
    key = pair_priority(ij[0], ij[1], p, round)
    low = pair_priority_low(ij[0], ij[1], p, round)
    for e in range(2):
        if body_inv_mass[ij[e]] > 0.0:
            wp.atomic_max(body_best, ij[e], key)
            wp.atomic_min(body_least, ij[e], low)


@wp.kernel
def color_pick(
    tid_offset: int,
    # Settings (the round on the device: the rounds run in a device-side loop)
    round_index: wp.array(dtype=wp.int32),
    last_round: int,
    phase: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    # In (this round's priorities)
    body_best: wp.array(dtype=wp.int64),
    body_least: wp.array(dtype=wp.int64),
    # Out: a body's mask is written only by the one pair that holds its maximum this round
    body_color_mask: wp.array(dtype=wp.int64),
    pair_color: wp.array(dtype=wp.int32),
    # Out: any writer stores 1
    pending: wp.array(dtype=wp.int32),
    overflow: wp.array(dtype=wp.int32),
):
    p = wp.tid() + tid_offset
    round = round_index[0]
    if pending[round] == 0 or p >= pair_count[0] or pair_color[p] != UNCOLORED:
        return
    ij = pair_body[p]
    i = ij[0]
    j = ij[1]
    key = pair_priority(i, j, p, round)
    low = pair_priority_low(i, j, p, round)
    dyn_i = body_inv_mass[i] > 0.0
    dyn_j = body_inv_mass[j] > 0.0
    is_max = (not dyn_i or body_best[i] == key) and (not dyn_j or body_best[j] == key)
    is_min = (not dyn_i or body_least[i] == low) and (not dyn_j or body_least[j] == low)
    if phase == 0 and not is_max:
        if not is_min:
            if round == last_round:
                pair_color[p] = COLOR_COUNT
                overflow[0] = 1
            else:
                pending[round + 1] = 1
        return
    if phase == 1 and not is_min:
        return
    used = wp.int64(0)
    if dyn_i:
        used = used | body_color_mask[i]
    if dyn_j:
        used = used | body_color_mask[j]
    color = int(COLOR_COUNT)
    for c in range(COLOR_COUNT):
        if color == COLOR_COUNT and (used & (wp.int64(1) << wp.int64(c))) == wp.int64(0):
            color = c
    pair_color[p] = color
    if color == COLOR_COUNT:
        overflow[0] = 1
        return
    bit = wp.int64(1) << wp.int64(color)
    if dyn_i:
        body_color_mask[i] = body_color_mask[i] | bit
    if dyn_j:
        body_color_mask[j] = body_color_mask[j] | bit


@wp.kernel
def color_next_round(round_index: wp.array(dtype=wp.int32), pending: wp.array(dtype=wp.int32),
                     busy: wp.array(dtype=wp.int32)):
    """One thread: the loop's next round, and whether it has pairs left (the loop's condition)."""
    following = round_index[0] + 1
    round_index[0] = following
    busy[0] = 0
    if following < ROUND_CAP:
        if pending[following] != 0:
            busy[0] = 1


@wp.kernel
def color_keys(
    tid_offset: int,
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_color: wp.array(dtype=wp.int32),
    sort_key: wp.array(dtype=wp.int32),
    sort_pair: wp.array(dtype=wp.int32),
):
    """Sort keys: the colour, or COLOR_COUNT + 1 for none (no points, or past the live count)."""
    p = wp.tid() + tid_offset
    key = int(COLOR_COUNT + 1)
    if p < pair_count[0]:
        c = pair_color[p]
        if c >= 0:
            key = c
    sort_key[p] = key
    sort_pair[p] = p


@wp.kernel
def color_bounds(
    tid_offset: int,
    count: int,
    sort_key: wp.array(dtype=wp.int32),
    sort_pair: wp.array(dtype=wp.int32),
    # Out
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
):
    """color_start[c] = first sorted entry of colour >= c; each start written by the one thread
    at its boundary (the last thread closes the colours after the last key)."""
    k = wp.tid() + tid_offset
    c = sort_key[k]
    color_pairs_sorted[k] = sort_pair[k]
    prev = int(-1)
    if k > 0:
        prev = sort_key[k - 1]
    for cc in range(prev + 1, wp.min(c, COLOR_COUNT + 1) + 1):
        color_start[cc] = k
    if k == count - 1:
        for cc in range(c + 1, COLOR_COUNT + 2):
            color_start[cc] = count


@wp.func
def color_range(color: int, color_start: wp.array(dtype=wp.int32), t: int) -> wp.vec2i:
    """[first, last) of ``color_pairs_sorted`` that thread ``t`` of a colour's launch handles: one
    pair per thread, except the overflow colour, whose pairs may share bodies and so are walked
    in order by thread 0 alone.  Threads past the colour's size get an empty range, so a launch
    may be sized by an upper bound (capturable launches)."""
    begin = color_start[color]
    end = color_start[color + 1]
    first = begin + t
    last = first + 1
    if color == COLOR_COUNT:
        last = end
        if t != 0:
            first = end
    return wp.vec2i(first, wp.min(last, end))


class _Site:
    pass


class PairColoring:
    """Scratch and launches of the colouring; ``run`` writes ``contacts.color_start`` and
    ``contacts.color_pairs_sorted``."""

    def __init__(self, body_count: int, capacity: int, device):
        self.device = device
        self.capacity = max(capacity, 1)
        n = max(body_count, 1)
        self.body_count = body_count
        self.body_best = wp.full(n, -1, dtype=wp.int64, device=device)
        self.body_least = wp.full(n, LEAST_EMPTY, dtype=wp.int64, device=device)
        self.body_color_mask = wp.zeros(n, dtype=wp.int64, device=device)
        self.pair_color = wp.zeros(self.capacity, dtype=wp.int32, device=device)
        self.pending = wp.zeros(ROUND_CAP + 1, dtype=wp.int32, device=device)
        self.round_index = wp.zeros(1, dtype=wp.int32, device=device)  # the round the loop is in
        self.busy = wp.zeros(1, dtype=wp.int32, device=device)  # the loop's condition
        self.overflow = wp.zeros(1, dtype=wp.int32, device=device)
        self.sort_key = wp.zeros(2 * self.capacity, dtype=wp.int32, device=device)
        self.sort_pair = wp.zeros(2 * self.capacity, dtype=wp.int32, device=device)
        self._pick_site = (_Site(), _Site())  # recorded launches per phase (launch.py)

    def run(self, body_inv_mass, contacts, live_count: int | None = None):
        """``live_count``: the pair count read on the host (direct stepping), or None to size
        every launch by the capacity and run all ROUND_CAP rounds (capturable)."""
        dev = self.device
        dim = self.capacity if live_count is None else min(live_count, self.capacity)
        self.pending.zero_()
        self.body_best.fill_(-1)
        self.body_least.fill_(LEAST_EMPTY)
        self.body_color_mask.zero_()
        if dim > 0:
            launch(color_init, dim, key=self, min_chunk=LIGHT_CHUNK, device=dev, inputs=[
                contacts.pair_count, contacts.pair_point_count, self.pair_color, self.pending])
            self.round_index.zero_()
            self.busy.fill_(1)

            def one_round():
                # atomics: one plain launch (Warp's CPU atomics are not atomic across launch chunks)
                wp.launch(color_claim, dim=dim, device=dev, **gpu_blocks(dev), inputs=[
                    self.round_index, body_inv_mass, contacts.pair_count, contacts.pair_body, self.pair_color,
                    self.pending, self.body_best, self.body_least])
                for phase in range(2):
                    launch(color_pick, dim, key=self._pick_site[phase], device=dev, inputs=[
                        self.round_index, ROUND_CAP - 1, phase, body_inv_mass, contacts.pair_count,
                        contacts.pair_body, self.body_best, self.body_least, self.body_color_mask, self.pair_color,
                        self.pending, self.overflow])
                wp.launch(color_next_round, dim=1, device=dev, inputs=[self.round_index, self.pending, self.busy])

            # the rounds run while some pair is pending: a device-side loop in a captured step
            # (a conditional while node), a loop reading the flag on the host when stepped directly
            wp.capture_while(self.busy, one_round)
            launch(color_keys, dim, key=self, min_chunk=LIGHT_CHUNK, device=dev, inputs=[
                contacts.pair_count, contacts.pair_body, self.pair_color, self.sort_key, self.sort_pair])
            wp.utils.radix_sort_pairs(self.sort_key, self.sort_pair, dim, 0, SORT_BITS)
            launch(color_bounds, dim, key=self, min_chunk=LIGHT_CHUNK, device=dev, inputs=[
                dim, self.sort_key, self.sort_pair, contacts.color_start, contacts.color_pairs_sorted])
        else:
            contacts.color_start.zero_()

    def take_overflow(self) -> bool:
        """Whether any pass since the last call left pairs to the overflow set (the flag is kept
        across passes, so a captured step's passes are read once, after the replay)."""
        # one int read back per Simulator.step call, after the steps (never inside one)
        hit = bool(self.overflow.numpy()[0])
        if hit:
            self.overflow.zero_()
        return hit

    def launch_bounds(self) -> list[int]:
        """Per-colour launch sizes that hold whatever the colouring produced: a colour's pairs
        share no dynamic body, so it has at most as many pairs as there are bodies; the overflow
        set may hold every pair (solvers/pair_overflow.py strides over it with fewer threads)."""
        bound = max(1, min(self.capacity, self.body_count))
        return [bound] * COLOR_COUNT + [self.capacity]
