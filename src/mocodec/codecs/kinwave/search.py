"""The search for the steps that meet a bound, or a bit rate, on the decoded output: a scale
search (secant in log-log space), the joint feedback of a first pass, time-adaptive steps per
segment, and the slack given away at the end; the final bytes are checked on the real
decoder (docs/kinwave.md)."""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from mocodec.codecs.kinwave.body import (
    code_channels,
    decode_body,
)
from mocodec.codecs.kinwave.encoder import (
    Encoder,
    Pass,
    influence,
)
from mocodec.errors import CodecError

MAX_PASSES = 8  # secant passes before falling back to halving
JOINT_FEEDBACK = 1.0  # share of a joint's measured slack (in octaves) its steps take on
SHORT_FRAMES = 512  # a body this short searches once per share of SHORT_SHARES, the smallest wins
SHORT_SHARES = (JOINT_FEEDBACK, 0.5, 0.0)
CORRECTIONS = 3  # passes that make the codes to blame for a first pass over a max bound finer (the default)
MISSED_SHARE = 0.5  # ... where all of them miss, the default lands again at this joint feedback, the smaller kept
SLACK_PASSES = 1  # rounds in which a max bound's final pass gives its slack away (use_slack)
SLACK_TRIES = 3  # passes a round tries, halving the codes that move the points over the bound
SEGMENT_SLACK_BELOW = 0.9  # ... with time-adaptive steps only when its worst error is under this share
ACCEPT = 0.95  # a max-error bound is met well enough at 95-100% of it
DEFAULT_ACCEPT = 0.9  # ... at effort 2, whose slack rounds take most of the rest back
DEFAULT_STOP = 0.8  # ... where its scale search stops (it aims at the middle of the accepted range)
LOW_EFFORT_ACCEPT = 0.85  # ... at effort 1 (any bound), which stops its search sooner and skips the slack rounds
MEAN_ACCEPT = 0.97  # a mean-error bound (smooth in the scale, so the search can aim closer)
SEGMENT_PASSES = 2  # passes of the per-segment search before the combination is fixed
MARGIN = 0.95  # a segment whose error was this close to the bound goes a code finer when combined
SEGMENT_ACCEPT = 0.8  # a segment's worst error is near enough to the bound at this share of it
ADAPTIVE_SEGMENTS = 4  # time-adaptive steps from this many segments on (on fewer, one scale is smaller)
RATE_TOLERANCE = 0.02
FILL_BELOW = 0.85  # a final max-bound pass under this share of the bound gives single codes their slack
FILL_TRIES = 8  # codes tried one at a time


class BoundSearch(Encoder):
    """The encoder's search for the steps that meet a bound (or a bit rate) on the decoded output."""

    feedback_share = JOINT_FEEDBACK
    checked: tuple[bytes, np.ndarray] | None = None  # the body the bound was last checked on, decoded

    @cached_property
    def moved_points(self) -> np.ndarray:
        """``(codes, points)``: which points each step code moves (:func:`.encoder.influence`)."""
        return influence(self.skeleton, self.cfg["error_measure"])

    def _adapt_joints(self, errors: np.ndarray, bound: float) -> float:
        """Correct the model's step shape by what a pass measured (max bounds): a joint whose
        points all stayed well below the worst one is coded finer than it needs (the model's
        uniform-noise error overstates quiet joints, whose coefficients mostly fall in the dead
        zone), so its steps grow by that slack (the clip's worst error over the worst among the
        points it moves), from the pass's ``errors (frames, points)``. Returns the scale factor
        that brings the pass's worst error to the middle of the accepted range."""
        err = errors.max(axis=0)
        worst = err.max()
        if worst <= 0:
            return 1.0
        self.joint_offsets = self._slack_codes(err, worst, self.feedback_share)
        return float(np.clip(bound * (1.0 + ACCEPT) / 2.0 / worst, 0.25, 4.0))

    def _slack_codes(self, errors: np.ndarray, reference: float, share: float = 1.0) -> np.ndarray:
        """Per step code, the 1/8 octaves (times ``share``, floored) between ``reference`` and
        the worst of ``errors (points,)`` among the points the code moves (the joints below it,
        and with ``shell`` its own bone's shell; the translations: all)."""
        moved = self.moved_points
        own = np.where(moved, errors, -np.inf).max(axis=1, initial=-np.inf)
        own[~moved.any(axis=1)] = errors.max()
        return np.floor(8.0 * share * np.log2(reference / np.maximum(own, reference * 2.0**-8)))

    def run(self) -> bytes:
        if self.frames == 0:
            return self.body(self.run_pass(self.codes(1.0)))
        if self.cfg["bits_per_second"] > 0:
            return self._to_rate(self.cfg["bits_per_second"] * self.frames / self.motion.fps / 8.0)
        if (
            self.cfg["segment_steps"]
            and self.cfg["error_measure"] != "mean"
            and np.count_nonzero(self.lay.padded) >= ADAPTIVE_SEGMENTS
        ):
            return self._to_bound_by_segment(self.cfg["max_error_cm"])
        if (
            self.frames <= SHORT_FRAMES
            and self.cfg["error_measure"] != "mean"
            and self.cfg["joint_feedback"]
            and self.cfg["effort"] >= 3
        ):
            return min(map(self.to_bound_with_share, SHORT_SHARES), key=len)
        return self._to_bound(self.cfg["max_error_cm"])

    def to_bound_with_share(self, share: float) -> bytes:
        """:meth:`_to_bound` with the joint feedback taking ``share`` of the slack. Where a max
        bound's search lands moves a short body a lot (its worst error is a handful of
        frames, and the first pass's slack sets every joint's step); three landings cost little
        on a short body, and the smallest wins (what it buys: docs/kinwave.md)."""
        self.feedback_share, self.joint_offsets = share, np.zeros_like(self.joint_offsets)
        return self._to_bound(self.cfg["max_error_cm"])

    def _search(
        self,
        measure,
        goal: float,
        accept: float,
        scale: float,
        exponent: float,
        sign: float = 1.0,
        stop: float = 1.0,
        seen: dict[bytes, tuple[float, Pass]] | None = None,
    ):
        """Find x = log(scale) / sign with ``measure`` (rising with x) in [accept * goal, goal]:
        extrapolate until the target is bracketed (first with ``exponent``, the model's
        d log measure / dx, then with the slope the last two passes measured), then secant steps
        inside the bracket, aiming at the range's middle; a pass in [min(stop, accept) * goal,
        goal] ends the search too. ``seen``: passes run already, by their codes. Returns (best
        pass meeting the goal or None, last x)."""
        lo = hi = None  # (x, log value, pass)
        previous = None  # the last (x, log value) before bracketing
        seen = {} if seen is None else seen
        x = math.log(scale) / sign
        aim = math.log(goal * (1.0 + accept) / 2.0)
        for _ in range(MAX_PASSES):
            codes = self.codes(math.exp(sign * x))
            if codes.tobytes() not in seen:
                ps = self.run_pass(codes)
                seen[codes.tobytes()] = (measure(ps), ps)
            value, ps = seen[codes.tobytes()]
            y = math.log(max(value, 1e-300))
            if value <= goal:
                if lo is None or x > lo[0]:
                    lo = (x, y, ps)
                if value >= min(stop, accept) * goal:
                    break
            elif hi is None or x < hi[0]:
                hi = (x, y, ps)
            if lo is not None and hi is not None:
                if hi[0] - lo[0] < 1e-3:
                    break
                slope = (hi[1] - lo[1]) / (hi[0] - lo[0])
                x = lo[0] + (aim - lo[1]) / slope if slope > 0 else (lo[0] + hi[0]) / 2
                if not lo[0] < x < hi[0]:
                    x = (lo[0] + hi[0]) / 2
            else:
                slope = exponent
                if previous is not None and abs(x - previous[0]) > 1e-9:
                    measured = (y - previous[1]) / (x - previous[0])
                    slope = measured if measured > 0.1 * exponent else exponent
                previous = (x, y)
                x = x + float(np.clip((aim - y) / slope, -3.0, 3.0))
        return (lo[2] if lo else None), x

    def _corrected_first(
        self, scale: float, bound: float, seen: dict[bytes, tuple[float, Pass]]
    ) -> tuple[Pass | None, bool]:
        """At the default effort, the scale search's first pass at ``scale`` (kept in ``seen``
        for the search), and where it breaks a max bound, up to CORRECTIONS passes in which
        each code that moves a point over the bound goes finer by the 1/8 octaves of that
        point's overshoot, the others as they were: (the first of them that meets the bound,
        else None: the scale search goes on; whether every correction missed). The max error
        jumps with single step codes, so a first pass aimed near the bound breaks it on most
        clips; the codes to blame then move, not every code, and the file lands smaller than
        where the scale search's next passes take it (docs/kinwave.md)."""
        codes = self.codes(scale)
        ps = self.run_pass(codes)
        seen[codes.tobytes()] = (error := self.pass_error(ps), ps)
        if error <= bound:
            return None, False
        for _ in range(CORRECTIONS):
            finer = np.minimum(self._slack_codes(self.pass_errors(ps).max(axis=0), bound), 0)
            ps = self.run_pass(np.clip(ps.steps + finer, 0, 255).astype(np.uint8), ps.offsets)
            if self.pass_error(ps) <= bound:
                return ps, False
        return None, True

    def use_slack(self, best: Pass, bound: float, below: float = math.inf) -> Pass:
        """Under a max bound, the final pass gives the slack to the codes whose points have it:
        each code coarser by the 1/8 octaves between the bound and the worst error among the
        points it moves; while the pass then breaks the bound, the codes that move a point now
        over it halve theirs and the others keep it (SLACK_TRIES passes a round, SLACK_PASSES
        rounds at most; segment offsets kept). The joint feedback set the codes' shape at the starting scale;
        at the final one, and near the bound, where the worst error jumps with single step
        codes, the points' errors differ again. A pass whose worst error is already ``below`` x
        bound or more is kept (the time-adaptive steps' segments take most of the slack). What
        the rounds buy and cost: docs/kinwave.md."""
        if self.cfg["error_measure"] == "mean":
            return best
        errors = self.pass_errors(best).max(axis=0)  # per point, over the frames
        for _ in range(SLACK_PASSES):
            if errors.max() >= below * bound:
                return best
            coarser = self._slack_codes(errors, bound)
            for _ in range(SLACK_TRIES):
                if not coarser.any():
                    break
                ps = self.run_pass(np.clip(best.steps + coarser, 0, 255).astype(np.uint8), best.offsets)
                trial = self.pass_errors(ps).max(axis=0)
                if trial.max() <= bound:
                    best, errors = ps, trial
                    break
                moving_over = self.moved_points[:, trial > bound].any(axis=1)
                coarser = np.where(moving_over, np.floor(coarser / 2.0), coarser)
            else:
                break
        return self.fill(self.scale_up(best, errors.max(), bound), bound)

    def fill(self, best: Pass, bound: float) -> Pass:
        """A final pass still under FILL_BELOW x bound (every code one step coarser together
        breaks the bound: the worst error jumps with single codes at a few frames) gives the
        codes their slack one at a time (FILL_TRIES codes at most): each code coarser by the
        1/8 octaves between the bound and the worst error among the points it moves, halved
        while that breaks the bound, kept if the body shrinks. Codes go in order of the
        slack times the nonzero coefficients of their channels (a joint that barely moves saves
        nothing)."""
        errors = self.pass_errors(best).max(axis=0)
        if errors.max() >= FILL_BELOW * bound:
            return best
        coded = np.count_nonzero(best.coeffs, axis=1)  # per channel: what a coarser step saves
        gain = self._slack_codes(errors, bound) * np.array([coded[rows].sum() for rows in code_channels(self.skeleton)])
        size = len(self.body(best))
        for code in np.argsort(-gain, kind="stable")[: min(FILL_TRIES, int(np.count_nonzero(gain > 0)))]:
            amount = int(self._slack_codes(errors, bound)[code])
            while amount > 0:
                steps = best.steps.astype(np.int64)
                steps[code] = min(steps[code] + amount, 255)
                ps = self.run_pass(steps.astype(np.uint8), best.offsets)
                trial = self.pass_errors(ps).max(axis=0)
                if trial.max() <= bound:
                    smaller = len(self.body(ps))
                    if smaller < size:  # (a coarser step rarely costs bytes: contexts)
                        best, errors, size = ps, trial, smaller
                    break
                amount //= 2
            if errors.max() >= FILL_BELOW * bound:
                break
        return best

    def scale_up(self, best: Pass, worst: float, bound: float) -> Pass:
        """A final pass still under ACCEPT x bound (the time-adaptive search can stop far below
        it when a seam makes one segment's error jump and the segment goes many codes finer)
        takes every code coarser together by the 1/8 octaves between its worst error and the
        bound, halved while that breaks the bound."""
        while worst < ACCEPT * bound:
            shift = int(np.floor(8.0 * math.log2(bound / max(worst, bound * 2.0**-8))))
            while shift > 0:
                steps = np.clip(best.steps.astype(np.int64) + shift, 0, 255).astype(np.uint8)
                if np.array_equal(steps, best.steps):
                    return best  # every code is already the coarsest (a motion that holds still)
                ps = self.run_pass(steps, best.offsets)
                trial = self.pass_errors(ps).max()
                if trial <= bound:
                    best, worst = ps, trial
                    break
                shift //= 2
            else:
                return best
        return best

    def _to_bound(self, bound: float) -> bytes:
        guess = self.first_scale()
        if self.cfg["error_measure"] != "mean" and self.cfg["joint_feedback"] and not self.joint_offsets.any():
            guess *= self._adapt_joints(self.pass_errors(self.starting_pass()), bound)
        if self.cfg["error_measure"] == "mean":  # (no slack rounds: a mean is smooth in the scale)
            accept = MEAN_ACCEPT
        else:
            accept = ACCEPT if self.cfg["effort"] >= 3 else DEFAULT_ACCEPT
        if self.cfg["effort"] <= 1:
            accept = min(accept, LOW_EFFORT_ACCEPT)
        # at effort 2 the slack rounds take the rest back: the secant steps that come closer
        # cost a pass each and bought 0.1-0.8% of the bytes (docs/kinwave.md)
        stop = DEFAULT_STOP if self.cfg["effort"] == 2 and self.cfg["error_measure"] != "mean" else 1.0
        seen: dict[bytes, tuple[float, Pass]] = {}
        best, missed = self._corrected_first(guess, bound, seen) if stop < 1.0 else (None, False)
        x = math.log(guess)
        if best is None:
            best, x = self._search(self.pass_error, bound, accept, guess, 1.0, stop=stop, seen=seen)
        for _ in range(60):
            if best is not None:
                body = self.body(self.use_slack(best, bound) if self.cfg["effort"] >= 2 else best)
                if self.error(self.decoded_body(body)) <= bound:  # the guarantee, on the real decoder
                    if missed and self.feedback_share == JOINT_FEEDBACK and self.cfg["joint_feedback"]:
                        return min(body, self.to_bound_with_share(MISSED_SHARE), key=len)
                    return body
            x -= math.log(2.0)
            ps = self.run_pass(self.codes(math.exp(x)))
            best = ps if self.pass_error(ps) <= bound else None
        raise CodecError(f"kinwave cannot reach {self.cfg['error_measure']} error {bound:g} cm")

    def _to_bound_by_segment(self, bound: float) -> bytes:
        """A max-error bound with time-adaptive steps: the joints' steps from the model's
        scale, then every segment's own offset (1/8 octave) searched so that its worst error
        lies in [SEGMENT_ACCEPT, 1] x bound, so quiet stretches no longer take the steps the busiest
        one needs. Segments meet at knots and seams, so the combination is checked as a whole
        and segments over the bound move finer until none is (else the single-scale search of
        :meth:`_to_bound` takes over); the final bytes are measured on the real decoder."""
        starts = self.lay.starts
        aim = bound * (1.0 + SEGMENT_ACCEPT) / 2.0

        def segment_errors(errors):
            return np.maximum.reduceat(errors.max(axis=1), starts)

        guess = self.first_scale()
        first = None
        if self.cfg["joint_feedback"]:
            errors = self.pass_errors(self.starting_pass())
            first = segment_errors(errors)
            guess *= self._adapt_joints(errors, bound)
        base = self.codes(guess)
        lowest, highest = max(-int(base.min()), -128), min(255 - int(base.max()), 127)
        passes: dict[bytes, tuple[Pass, np.ndarray]] = {}

        def run(offsets):
            key = offsets.astype(np.int8).tobytes()
            if key not in passes:
                ps = self.run_pass(base, offsets)
                passes[key] = ps, segment_errors(self.pass_errors(ps))
            return passes[key]

        offsets = np.zeros(starts.size, dtype=np.int64)
        if first is not None:  # segments quieter in the first pass start coarser (half their slack)
            offsets = np.clip(np.round(4.0 * np.log2(first.max() / np.maximum(first, 1e-12))), 0, highest).astype(
                np.int64
            )
        feasible = np.full(starts.size, lowest - 1)  # the largest offset seen within the bound
        closest = np.zeros(starts.size)  # the error seen there
        failed = np.full(starts.size, highest + 1)  # the smallest offset seen over it
        for _ in range(SEGMENT_PASSES):
            _, seg = run(offsets)
            ok = seg <= bound
            closest = np.where(ok & (offsets >= feasible), seg, closest)
            feasible = np.where(ok, np.maximum(feasible, offsets), feasible)
            failed = np.where(ok, failed, np.minimum(failed, offsets))
            settled = (ok & (seg >= SEGMENT_ACCEPT * bound)) | (failed - feasible <= 1)
            if settled.all():
                break
            move = np.round(8.0 * np.log2(aim / np.maximum(seg, 1e-12)))
            target = np.clip(offsets + np.where(ok, np.maximum(move, 1), np.minimum(move, -1)), lowest, highest)
            target = np.where((target <= feasible) | (target >= failed), (feasible + failed) // 2, target)
            offsets = np.where(settled, offsets, target).astype(np.int64)
        offsets = np.where(feasible >= lowest, feasible, np.minimum(offsets, failed - 1))
        offsets = np.maximum(offsets - (closest > MARGIN * bound), lowest)  # neighbours move the errors too
        for _ in range(SEGMENT_PASSES + 3):
            ps, seg = run(offsets)
            over = seg > bound
            if not over.any():
                body = self.body(self.use_slack(ps, bound, SEGMENT_SLACK_BELOW))
                if self.error(self.decoded_body(body)) <= bound:  # the guarantee, on the real decoder
                    return body
                over[:] = True
            if (offsets[over] == lowest).all():
                break
            finer = np.maximum(np.ceil(8.0 * np.log2(np.maximum(seg, bound) / bound)), 1)
            offsets = np.where(over, np.maximum(offsets - finer, lowest), offsets).astype(np.int64)
        return self._to_bound(bound)  # what the segments cannot fix (constant channels): one scale

    def decoded_body(self, body: bytes) -> np.ndarray:
        """What the decoder makes of ``body`` ``(C, T)`` on the skeleton it will be given (a
        constant translation is coded about that skeleton's offsets); kept for
        :meth:`decoded_frame`."""
        decoded = decode_body(body, self.output_skeleton, self.frames).T
        self.checked = (body, decoded)
        return decoded

    def decoded_frame(self, body: bytes, frame: int) -> np.ndarray:
        """Frame ``frame`` ``(C,)`` of what the decoder makes of ``body``: from the bound's
        check when that decoded this body, else decoded anew."""
        if self.checked is not None and self.checked[0] is body:
            return self.checked[1][:, frame]
        return decode_body(body, self.output_skeleton, self.frames)[frame]

    def _to_rate(self, budget_bytes: float) -> bytes:
        # size / budget falls as the scale rises: search on x = -log(scale)
        best, _ = self._search(
            lambda ps: len(self.body(ps)) / budget_bytes, 1.0, 1 - RATE_TOLERANCE, 1.0, 0.8, sign=-1.0
        )
        return self.body(best if best is not None else self.run_pass(self.codes(2.0**40)))
