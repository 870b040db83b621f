"""Dead reckoning (000 §7.7): a ghost model extrapolated from the last update, and an update
whenever the ghost strays further than a threshold (fig. 7-9, 7-10).

Per group of channels (one channel, or a joint's rotation or translation channels) the ghost
is ``base + v (t - u) [+ a (t - u)^2 / 2]`` since the update at frame ``u`` (7-20, 7-19). At
frame ``t`` the coder compares the ghost with the input (the absolute difference for one
channel, the Euclidean norm over a group's channels) and, above the threshold, sends an
update: for each channel of the group the quantised difference between the input and the
ghost (not the absolute value: the difference needs fewer levels), and the quantised change
of velocity (and acceleration), the velocity estimated by a least-squares quadratic fit over
7 samples centred on ``t`` (hence 3 frames of delay). Update values are taken after the
quantiser (fig. 7-10), so encoder and decoder ghosts are the same. Which groups update at
each frame is sent as a flag per group and frame (the update timestamps), range coded.
"""

from __future__ import annotations

import numpy as np

from mocodec.kernels import kernel

HALF_WINDOW = 3
# derivatives of the least-squares quadratic through 7 samples, at the centre
VELOCITY_TAPS = np.array([-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0]) / 28.0
ACCELERATION_TAPS = np.array([5.0, 0.0, -3.0, -4.0, -3.0, 0.0, 5.0]) / 42.0


@kernel
def run(
    x_ext, flags, values, decode, groups, group_start, thr, pstep, vstep, astep, use_acc, base, vel, acc, age, hist
):
    """Code (or decode) ``n = flags.shape[0]`` frames. ``x_ext (n + 6, K)`` holds the input
    with 3 frames of context either side (encoding only); ``groups`` lists the channels of
    group g at ``groups[group_start[g]:group_start[g + 1]]``. State: ``base, vel, acc (K,)``,
    ``age (G,)`` frames since each group's update, ``hist`` a histogram of update intervals.
    Fills ``flags (n, G)`` and the update rows ``values`` (encoding) or reads them
    (decoding); returns (decoded frames, rows used)."""
    n, ng = flags.shape
    k_all = base.size
    out = np.empty((n, k_all))
    row = 0
    for t in range(n):
        for g in range(ng):
            a, b = group_start[g], group_start[g + 1]
            s = age[g]
            if decode:
                update = flags[t, g] == 1
            else:
                err = 0.0
                for i in range(a, b):
                    k = groups[i]
                    d = x_ext[t + HALF_WINDOW, k] - (base[k] + vel[k] * s + 0.5 * acc[k] * s * s)
                    err += d * d
                update = np.sqrt(err) > thr[groups[a]]
                flags[t, g] = 1 if update else 0
            if update:
                for i in range(a, b):
                    k = groups[i]
                    ghost = base[k] + vel[k] * s + 0.5 * acc[k] * s * s
                    v_now = vel[k] + acc[k] * s
                    if not decode:
                        x = x_ext[t + HALF_WINDOW, k]
                        v_est = 0.0
                        a_est = 0.0
                        for j in range(7):
                            v_est += VELOCITY_TAPS[j] * x_ext[t + j, k]
                            a_est += ACCELERATION_TAPS[j] * x_ext[t + j, k]
                        values[row, 0] = int(np.round((x - ghost) / pstep[k]))
                        values[row, 1] = int(np.round((v_est - v_now) / vstep[k]))
                        if use_acc:
                            values[row, 2] = int(np.round((a_est - acc[k]) / astep[k]))
                    base[k] = ghost + values[row, 0] * pstep[k]
                    vel[k] = v_now + values[row, 1] * vstep[k]
                    if use_acc:
                        acc[k] = acc[k] + values[row, 2] * astep[k]
                    row += 1
                hist[min(s, hist.size - 1)] += 1
                age[g] = 0
            for i in range(a, b):
                k = groups[i]
                s2 = age[g]
                out[t, k] = base[k] + vel[k] * s2 + 0.5 * acc[k] * s2 * s2
            age[g] += 1
    return out, row
