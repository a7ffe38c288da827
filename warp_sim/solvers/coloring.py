"""Graph colouring of body-body contact pairs, so Gauss-Seidel can run in parallel.

Two pairs that share a dynamic body must not be solved at the same time (both would write that
body's velocity).  Pairs of one colour share no dynamic body, so a colour is one parallel
launch; colours run one after another, which keeps the sweep Gauss-Seidel.

The colouring is Box2D v3's greedy one: walk the pairs in their sorted (i, j) order and give
each the lowest colour that neither of its dynamic bodies uses yet (a bit mask per body).
Static bodies take no colour: any number of pairs may touch the ground at once.  A pair that
finds none of the COLOR_COUNT colours free goes to the overflow set, solved by one thread.
The walk is sequential (one thread), so the result is the same on every run and device;
it costs a few tens of nanoseconds per pair.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

COLOR_COUNT = 24  # fits the int32 masks; the last bucket (index COLOR_COUNT) is the overflow set


@wp.kernel
def color_pairs(
    # Model
    body_inv_mass: wp.array(dtype=float),
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Scratch
    body_color_mask: wp.array(dtype=wp.int32),
    pair_color: wp.array(dtype=wp.int32),
    color_cursor: wp.array(dtype=wp.int32),
    # Out
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
):
    count = pair_count[0]
    for c in range(COLOR_COUNT + 2):
        color_start[c] = 0
    for p in range(count):
        color = int(-1)
        if pair_point_count[p] > 0:
            ij = pair_body[p]
            i = ij[0]
            j = ij[1]
            dyn_i = body_inv_mass[i] > 0.0
            dyn_j = body_inv_mass[j] > 0.0
            used = int(0)
            if dyn_i:
                used = used | body_color_mask[i]
            if dyn_j:
                used = used | body_color_mask[j]
            color = COLOR_COUNT
            for c in range(COLOR_COUNT):
                if color == COLOR_COUNT and (used & (1 << c)) == 0:
                    color = c
            if color < COLOR_COUNT:
                if dyn_i:
                    body_color_mask[i] = body_color_mask[i] | (1 << color)
                if dyn_j:
                    body_color_mask[j] = body_color_mask[j] | (1 << color)
            color_start[color + 1] = color_start[color + 1] + 1
        pair_color[p] = color
    # counts -> starts, then place the pairs colour by colour (in pair order within a colour)
    for c in range(COLOR_COUNT + 1):
        color_start[c + 1] = color_start[c + 1] + color_start[c]
        color_cursor[c] = color_start[c]
    for p in range(count):
        c = pair_color[p]
        if c >= 0:
            color_pairs_sorted[color_cursor[c]] = p
            color_cursor[c] = color_cursor[c] + 1
        ij = pair_body[p]
        body_color_mask[ij[0]] = 0
        body_color_mask[ij[1]] = 0


@wp.func
def color_range(color: int, color_start: wp.array(dtype=wp.int32), t: int) -> wp.vec2i:
    """[first, last) of ``color_pairs_sorted`` that thread ``t`` of a colour's launch handles: one
    pair per thread, except the overflow colour, whose pairs may share bodies and so are walked
    in order by thread 0 alone."""
    begin = color_start[color]
    end = color_start[color + 1]
    first = begin + t
    last = first + 1
    if color == COLOR_COUNT:
        last = end
        if t != 0:
            first = end
    return wp.vec2i(first, wp.min(last, end))
