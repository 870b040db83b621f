"""Perceptual studies of the second thesis, run in the viewer's browser page.

- **DSCQS** (001 §6.4.1, ITU-R BT.500): each case shows the reference and the coded clip twice,
  as A and B in a random order the participant is not told (A B A B), then asks a score of 1-5
  (Bad, Poor, Fair, Good, Excellent) for each. The difference (reference - coded) of a case,
  averaged over participants, is its DMOS.
- **2AFC staircase** (001 §5.4, after García-Pérez 1998): the original and a clip coded by
  ``primitives`` at t_L (t_U = 2 t_L) play side by side, the original on a random side; the
  participant picks the more visually appealing and smooth one. Two correct answers in a row
  lower t_L by the step, a wrong one raises it (two-up-one-down); the threshold is the mean of
  the last three reversal points. The thesis starts at 0.024 with a step of 0.002.

A study is configured by a small JSON file (see ``docs/viewer.md``); its results are saved as
JSON, one file per session, and ``mocodec study report`` computes the DMOS of every case and
the thresholds, each with a 95% confidence interval over participants.
"""

from __future__ import annotations

import datetime
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocodec import moc, ratecontrol
from mocodec.codecs import get_codec
from mocodec.errors import FormatError, MocodecError
from mocodec.formats import load
from mocodec.formats.fileio import atomic_write
from mocodec.formats.pagejson import base64_f32, body_or_none, orientations
from mocodec.motion import Motion

KINDS = ("dscqs", "2afc")
RENDERINGS = ("body", "sticks")  # what the trials show: the mannequin, or stick figures
SCORES = {1: "Bad", 2: "Poor", 3: "Fair", 4: "Good", 5: "Excellent"}


@dataclass
class StudyConfig:
    kind: str
    clips: list[Path]
    seed: int = 1
    speed: float = 1.0  # playback speed of the page
    max_frames: int = 0  # clips cut to this many frames (0: whole)
    cases: list[dict] = field(default_factory=list)  # dscqs
    codec: str = "primitives"  # 2afc
    knob: str = "t_lower"
    start: float = 0.024
    step: float = 0.002
    floor: float = 0.002
    reversals: int = 6
    average_last: int = 3
    max_trials: int = 40
    rendering: str = "body"  # one of RENDERINGS, recorded with every trial


def load_config(path: str | Path) -> StudyConfig:
    """A study's configuration; FormatError naming the file and what is wrong."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise FormatError(path, getattr(e, "lineno", None), f"not a readable JSON study configuration ({e})") from None
    if not isinstance(doc, dict) or doc.get("kind") not in KINDS:
        raise FormatError(path, None, f'"kind" must be one of {", ".join(KINDS)}')
    known = set(StudyConfig.__dataclass_fields__)
    unknown = sorted(set(doc) - known)
    if unknown:
        raise FormatError(path, None, f"unknown setting {unknown[0]!r} (settings: {', '.join(sorted(known))})")
    clips = doc.get("clips")
    if not isinstance(clips, list) or not clips:
        raise FormatError(path, None, '"clips" must be a non-empty list of motion files')
    cfg = StudyConfig(**{**doc, "clips": [path.parent / c for c in clips]})
    if cfg.rendering not in RENDERINGS:
        raise FormatError(path, None, f'"rendering" must be one of {", ".join(RENDERINGS)}, not {cfg.rendering!r}')
    if cfg.kind == "dscqs":
        if not cfg.cases:
            raise FormatError(path, None, 'a dscqs study needs "cases": [{"clip": 0, "codec": "spiht", "ratio": 40}]')
        allowed = {"clip", "codec", "knobs", *ratecontrol.TARGETS}
        for k, case in enumerate(cfg.cases):
            if not isinstance(case, dict) or not 0 <= int(case.get("clip", -1)) < len(clips) or "codec" not in case:
                raise FormatError(path, None, f"case {k}: needs a clip index below {len(clips)} and a codec")
            if set(case) - allowed:
                raise FormatError(
                    path,
                    None,
                    f"case {k}: unknown key {sorted(set(case) - allowed)[0]!r} (keys: "
                    f'{", ".join(sorted(allowed))}; knobs go in "knobs")',
                )
    elif not (cfg.step > 0 and cfg.start > 0 and cfg.average_last >= 1 and cfg.reversals >= cfg.average_last):
        raise FormatError(path, None, "2afc: start and step must be positive, reversals >= average_last >= 1")
    return cfg


def _clip(motion: Motion) -> dict:
    """A clip for the page: joint positions (metres) and orientations, every frame."""
    return {"positions": base64_f32(motion.positions_m()), "quats": orientations(motion)}


class Study:
    """One participant's session: trials out, answers in, results at the end."""

    def __init__(self, cfg: StudyConfig, participant: str):
        self.cfg, self.participant = cfg, participant
        self.motions = [load(p) for p in cfg.clips]
        if cfg.max_frames:
            self.motions = [m[: cfg.max_frames] for m in self.motions]
        # each clip's mannequin, made once for all its trials
        self.bodies = {
            id(m): body_or_none(m.skeleton, m.channels[0]) if cfg.rendering == "body" else None for m in self.motions
        }
        self.rng = np.random.default_rng(cfg.seed)
        self.trials: list[dict] = []
        self.started = _now()
        self.current: dict | None = None

    @property
    def done(self) -> bool:
        raise NotImplementedError

    def trial(self) -> dict:
        """The next trial, as the page shows it."""
        raise NotImplementedError

    def answer(self, reply: dict) -> None:
        """Record the participant's answer to the current trial (MocodecError if it is malformed)."""
        raise NotImplementedError

    def _frame(self, motion: Motion, index: int, total: int | None) -> dict:
        return {
            "kind": self.cfg.kind,
            "index": index,
            "total": total,
            "fps": motion.fps,
            "frames": motion.num_frames,
            "parents": [int(p) for p in motion.skeleton.parents],
            "speed": self.cfg.speed,
            "rendering": self.cfg.rendering,
            "body": self.bodies[id(motion)],
        }

    def results(self) -> dict:
        return {
            "kind": self.cfg.kind,
            "participant": self.participant,
            "started": self.started,
            "finished": _now(),
            "config": {**self.cfg.__dict__, "clips": [str(p) for p in self.cfg.clips]},
            "trials": self.trials,
        }

    def save(self, folder: str | Path) -> Path:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.datetime.now().strftime("%Y%m%dT%H%M%S")
        path = folder / f"study-{self.cfg.kind}-{self.participant}-{stamp}.json"
        atomic_write(path, json.dumps(self.results(), indent=1, default=float))
        return path


class Dscqs(Study):
    def __init__(self, cfg: StudyConfig, participant: str):
        super().__init__(cfg, participant)
        self.reference_first = self.rng.random(len(cfg.cases)) < 0.5  # is the reference A?

    @property
    def done(self) -> bool:
        return len(self.trials) >= len(self.cfg.cases)

    def trial(self) -> dict:
        k = len(self.trials)
        case = self.cfg.cases[k]
        motion = self.motions[int(case["clip"])]
        codec = get_codec(case["codec"], **case.get("knobs", {}))
        target = next(((t, case[t]) for t in ratecontrol.TARGETS if t in case), None)
        if target is not None:
            codec = ratecontrol.configure(codec, motion, target[0], float(target[1]))
        trip = moc.round_trip(motion, codec)
        ref, cod = _clip(motion), _clip(trip.decoded)
        a_is_ref = bool(self.reference_first[k])
        self.current = {
            "case": k,
            "clip": self.cfg.clips[int(case["clip"])].name,
            "codec": codec.get_config(),
            "ratio": motion.raw_bits / 8 / len(trip.data),
            "reference": "A" if a_is_ref else "B",
            "rendering": self.cfg.rendering,
        }
        return {
            **self._frame(motion, k, len(self.cfg.cases)),
            "A": ref if a_is_ref else cod,
            "B": cod if a_is_ref else ref,
            "sequence": ["A", "B", "A", "B"],
            "scores": SCORES,
        }

    def answer(self, reply: dict) -> None:
        try:
            a, b = int(reply["scores"]["A"]), int(reply["scores"]["B"])
        except (KeyError, TypeError, ValueError):
            raise MocodecError('a DSCQS answer is {"scores": {"A": 1-5, "B": 1-5}}') from None
        if a not in SCORES or b not in SCORES or self.current is None:
            raise MocodecError("scores must be 1-5, for the case shown")
        ref, cod = (a, b) if self.current["reference"] == "A" else (b, a)
        self.trials.append({**self.current, "score_reference": ref, "score_coded": cod, "difference": ref - cod})
        self.current = None


class Staircase(Study):
    """The two-up-one-down 2AFC staircase on ``cfg.knob`` of ``cfg.codec``."""

    def __init__(self, cfg: StudyConfig, participant: str):
        super().__init__(cfg, participant)
        self.value, self.streak = cfg.start, 0
        self.direction = 0
        self.reversals: list[float] = []

    @property
    def done(self) -> bool:
        return len(self.reversals) >= self.cfg.reversals or len(self.trials) >= self.cfg.max_trials

    @property
    def threshold(self) -> float | None:
        last = self.reversals[-self.cfg.average_last :]
        return float(np.mean(last)) if len(last) == self.cfg.average_last else None

    def trial(self) -> dict:
        k = len(self.trials)
        motion = self.motions[k % len(self.motions)]  # the clips take turns
        codec = get_codec(self.cfg.codec, **{self.cfg.knob: self.value})
        distorted = _clip(moc.round_trip(motion, codec).decoded)
        original_left = bool(self.rng.random() < 0.5)
        self.current = {
            "trial": k,
            "clip": self.cfg.clips[k % len(self.motions)].name,
            "value": self.value,
            "original": "left" if original_left else "right",
            "rendering": self.cfg.rendering,
        }
        ref = _clip(motion)
        return {
            **self._frame(motion, k, None),
            "left": ref if original_left else distorted,
            "right": distorted if original_left else ref,
        }

    def answer(self, reply: dict) -> None:
        choice = reply.get("choice") if isinstance(reply, dict) else None
        if choice not in ("left", "right") or self.current is None:
            raise MocodecError('a 2AFC answer is {"choice": "left" | "right"}, for the pair shown')
        correct = choice == self.current["original"]
        self.trials.append({**self.current, "choice": choice, "correct": correct})
        self.current = None
        if correct:
            self.streak += 1
            if self.streak == 2:  # two up: harder
                self.streak = 0
                self._move(-1)
        else:  # one down: easier
            self.streak = 0
            self._move(+1)

    def _move(self, direction: int) -> None:
        if self.direction and direction != self.direction:
            self.reversals.append(self.value)
        self.direction = direction
        self.value = max(round(self.value + direction * self.cfg.step, 12), self.cfg.floor)

    def results(self) -> dict:
        return {**super().results(), "reversals": self.reversals, "threshold": self.threshold}


def start(cfg: StudyConfig, participant: str) -> Study:
    return Dscqs(cfg, participant) if cfg.kind == "dscqs" else Staircase(cfg, participant)


def _now() -> str:
    return datetime.datetime.now().isoformat(timespec="seconds")


# ----- the report ------------------------------------------------------------------------------------
def mean_ci(values: list[float]) -> dict:
    """Mean and 95% confidence interval (Student's t) of ``values``."""
    from scipy import stats

    x = np.asarray(values, dtype=np.float64)
    n = x.size
    half = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n)) if n > 1 else float("nan")
    return {"n": int(n), "mean": float(x.mean()), "ci95": [float(x.mean() - half), float(x.mean() + half)]}


def report(paths: list[str | Path]) -> dict:
    """DMOS of every DSCQS case and the 2AFC thresholds, over the result files given."""
    cases: dict[str, list[float]] = {}
    thresholds: list[float] = []
    for p in paths:
        try:
            doc = json.loads(Path(p).read_text())
            kind = doc["kind"]
            if kind == "dscqs":
                for t in doc["trials"]:
                    label = f"{t['clip']} {t['codec']['codec']} {t['ratio']:.1f}:1"
                    cases.setdefault(label, []).append(float(t["difference"]))
            elif kind == "2afc":
                if doc.get("threshold") is not None:
                    thresholds.append(float(doc["threshold"]))
            else:
                raise KeyError("kind")
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise FormatError(p, None, f"not a study result file ({type(e).__name__}: {e})") from None
    return {
        "dmos": {label: mean_ci(d) for label, d in sorted(cases.items())},
        "threshold_t_lower": mean_ci(thresholds) if thresholds else None,
    }
