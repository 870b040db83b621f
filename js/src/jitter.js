// A receiver-side jitter buffer (stream/jitter.py): frames arrive in bursts; they play out on the
// stream's own clock DELAY_S behind the newest arrival, the clock slewing at most 1% toward the
// delay the last WINDOW_S of arrivals needed; between frames the pose is interpolated, past the
// newest frame it holds, a gap holds the frame before it until a late packet fills it.

export const DELAY_S = 0.1;
const WINDOW_S = 2.0;
const SLEW = 0.01;
const KEEP_S = 2.0;

/**
 * A receiver-side jitter buffer (stream/jitter.py): frames arrive in bursts; they play out on the
 * stream's own clock DELAY_S behind the newest arrival, the clock slewing at most 1% toward the
 * delay the last WINDOW_S of arrivals needed; between frames the pose is interpolated, past the
 * newest frame it holds, a gap holds the frame before it until a late packet fills it.
 */
export class JitterBuffer {
  /**
   * @param {number} fps
   * @param {number} channels
   * @param {number} [delayS] how far behind the newest arrival frames play
   */
  constructor(fps, channels, delayS = DELAY_S) {
    this.fps = fps;
    this.channels = channels;
    this.delayS = delayS;
    this.frames = []; // Float64Array per frame, from stream frame `first`
    this.held = [];
    this.first = 0;
    this.origin = null; // receiver time (s) at which stream frame 0 plays
    this.recent = []; // [arrival, the origin it needed], a sliding maximum
    this.clock = null;
    this.late = 0;
  }

  /**
   * @param {Float64Array} frames count x channels, row-major
   * @param {number} firstFrame the stream frame of the first
   * @param {number} arrivalS when they arrived (s, the receiver's clock)
   */
  push(frames, firstFrame, arrivalS) {
    const C = this.channels;
    const count = frames.length / C;
    if (!count) return;
    const rows = Array.from({ length: count }, (_, k) => frames.slice(k * C, (k + 1) * C));
    const newest = firstFrame + count - 1;
    const due = arrivalS + this.delayS - newest / this.fps;
    if (this.origin === null) this.origin = due;
    else if (arrivalS > this.origin + firstFrame / this.fps) {
      this.late += Math.min(count, Math.ceil((arrivalS - this.origin) * this.fps - firstFrame));
      this.origin = arrivalS - firstFrame / this.fps;
    }
    while (this.recent.length && this.recent[0][0] < arrivalS - WINDOW_S) this.recent.shift();
    while (this.recent.length && this.recent.at(-1)[1] <= due) this.recent.pop();
    this.recent.push([arrivalS, due]);
    if (!this.frames.length) {
      this.frames = rows;
      this.held = rows.map(() => false);
      this.first = firstFrame;
      return;
    }
    let end = this.first + this.frames.length;
    for (; end < firstFrame; end++) { // a gap: hold the last frame over it
      this.frames.push(this.frames.at(-1));
      this.held.push(true);
    }
    for (let f = Math.max(firstFrame, this.first); f < Math.min(end, newest + 1); f++) {
      if (this.held[f - this.first]) { // a late packet fills what was held
        this.frames[f - this.first] = rows[f - firstFrame];
        this.held[f - this.first] = false;
      }
    }
    for (let f = Math.max(end, firstFrame); f <= newest; f++) {
      this.frames.push(rows[f - firstFrame]);
      this.held.push(false);
    }
  }

  /**
   * @param {number} nowS
   * @returns {number | null} the fractional stream frame that plays at `nowS`, null before the first
   */
  frameAt(nowS) {
    if (this.origin === null) return null;
    if (this.clock !== null && nowS > this.clock && this.recent.length) {
      const step = SLEW * (nowS - this.clock);
      this.origin = Math.min(Math.max(this.recent[0][1], this.origin - step), this.origin + step);
    }
    this.clock = this.clock === null ? nowS : Math.max(this.clock, nowS);
    return (nowS - this.origin) * this.fps;
  }

  /**
   * @param {number} nowS
   * @returns {Float64Array | null} the channels to show at `nowS` (interpolated), null before the first frame
   */
  pose(nowS) {
    const at = this.frameAt(nowS);
    if (at === null || !this.frames.length) return null;
    const k = Math.min(Math.max(at - this.first, 0), this.frames.length - 1);
    const i = Math.floor(k);
    const w = k - i;
    let pose = this.frames[i];
    if (w !== 0 && i + 1 < this.frames.length) {
      const next = this.frames[i + 1];
      pose = pose.map((v, c) => (1 - w) * v + w * next[c]);
    }
    const drop = Math.min(Math.floor(Math.max(at - this.first - KEEP_S * this.fps, 0)), this.frames.length - 1);
    if (drop > 0) {
      this.frames.splice(0, drop);
      this.held.splice(0, drop);
      this.first += drop;
    }
    return pose;
  }
}
