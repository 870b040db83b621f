"""A receiver-side jitter buffer: decoded frames arrive in bursts (a packet of several frames,
a relay tick, network jitter); a viewer shows them smoothly at the sender's frame rate.

Frames are played out on the stream's own clock, ``delay_s`` behind the newest arrival's
frame time: the playout time of frame ``f`` is ``origin + f / fps``, where ``origin`` is set by
the first frame's arrival plus the delay. The delay the arrivals of the last WINDOW_S needed
(the latest of them, ``delay_s`` ahead) is where the playout clock heads, running up to SLEW
faster or slower until it is there, so the delay follows the jitter unseen; a burst that
arrives after its own first frame should have played moves the clock back at once (the pose
holds a moment). Between frames the pose is interpolated
linearly (the channels are continuous: the live decoder's output); past the newest frame it is
held.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from mocodec.errors import CodecError

DELAY_S = 0.1  # how far behind the arrivals the playout starts
WINDOW_S = 2.0  # the arrivals a shorter delay must still have played on time
SLEW = 0.01  # the playout clock runs at most this much faster or slower while the delay follows the jitter
KEEP_S = 2.0  # seconds of frames kept behind the playout point


class JitterBuffer:
    """Frames in (with their stream frame number and arrival time), a smooth pose out."""

    def __init__(self, fps: float, channels: int, delay_s: float = DELAY_S):
        if not fps > 0 or not delay_s >= 0:
            raise CodecError(f"jitter buffer: fps {fps} and delay {delay_s} s must be positive")
        self.fps, self.delay_s = fps, delay_s
        self.frames = np.zeros((0, channels))
        self.held = np.zeros(0, dtype=bool)  # frames not received (yet): the one before, held
        self.first = 0  # stream frame number of self.frames[0]
        self.origin: float | None = None  # wall time at which stream frame 0 plays
        self.late = 0  # frames that arrived after their playout time
        self.recent: deque[tuple[float, float]] = deque()  # (arrival, the origin it needed)
        self.clock: float | None = None  # the last time a pose was asked for

    def push(self, frames: np.ndarray, first_frame: int, arrival_s: float) -> None:
        """Frames ``first_frame ...`` arrived at ``arrival_s`` (seconds on the receiver's clock)."""
        frames = np.atleast_2d(np.asarray(frames, dtype=np.float64))
        if not len(frames):
            return
        newest = first_frame + len(frames) - 1
        due = arrival_s + self.delay_s - newest / self.fps  # the origin that plays the newest delay_s after it came
        if self.origin is None:
            self.origin = due
        elif arrival_s > self.origin + first_frame / self.fps:  # late: its first frame should have played
            self.late += int(min(len(frames), np.ceil((arrival_s - self.origin) * self.fps - first_frame)))
            self.origin = arrival_s - first_frame / self.fps
        while self.recent and self.recent[0][0] < arrival_s - WINDOW_S:
            self.recent.popleft()
        while self.recent and self.recent[-1][1] <= due:  # a sliding maximum
            self.recent.pop()
        self.recent.append((arrival_s, due))
        if not len(self.frames):
            self.frames, self.first = frames.copy(), first_frame
            self.held = np.zeros(len(frames), dtype=bool)
            return
        end = self.first + len(self.frames)
        if first_frame > end:  # a gap (a packet late or lost): hold the last frame over it
            self.frames = np.vstack((self.frames, np.repeat(self.frames[-1:], first_frame - end, axis=0)))
            self.held = np.append(self.held, np.ones(first_frame - end, dtype=bool))
            end = first_frame
        if first_frame < end:  # frames we have: a late packet fills what was held
            a, b = max(first_frame, self.first), min(end, newest + 1)
            if a < b:
                fill = self.held[a - self.first : b - self.first]
                self.frames[a - self.first : b - self.first][fill] = frames[a - first_frame : b - first_frame][fill]
                self.held[a - self.first : b - self.first] = False
            frames = frames[end - first_frame :]
        self.frames = np.vstack((self.frames, frames))
        self.held = np.append(self.held, np.zeros(len(frames), dtype=bool))

    def frame_at(self, now_s: float) -> float | None:
        """The (fractional) stream frame that plays at ``now_s``, or None before the first."""
        if self.origin is None:
            return None
        if self.clock is not None and now_s > self.clock and self.recent:
            need = self.recent[0][1]  # the latest origin the recent arrivals needed
            step = SLEW * (now_s - self.clock)
            self.origin = float(np.clip(need, self.origin - step, self.origin + step))
        self.clock = now_s if self.clock is None else max(self.clock, now_s)
        return (now_s - self.origin) * self.fps

    def pose(self, now_s: float) -> np.ndarray | None:
        """The channels to show at ``now_s``: interpolated between the two frames around the
        playout point, the first frame before it, the newest frame past the end."""
        at = self.frame_at(now_s)
        if at is None or not len(self.frames):
            return None
        k = float(np.clip(at - self.first, 0.0, len(self.frames) - 1))
        i = int(np.floor(k))
        w = k - i
        if w == 0.0 or i + 1 >= len(self.frames):
            pose = self.frames[i].copy()
        else:
            pose = (1 - w) * self.frames[i] + w * self.frames[i + 1]
        drop = min(int(max(at - self.first - KEEP_S * self.fps, 0)), len(self.frames) - 1)
        if drop:
            self.frames, self.held, self.first = self.frames[drop:], self.held[drop:], self.first + drop
        return pose
