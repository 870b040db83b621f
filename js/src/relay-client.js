// Joins a relay room as a viewer over WebSocket and keeps each avatar's decoded motion in a jitter
// buffer: `new RelayClient(url, {room, token})`, `await client.connect()`, then `client.avatars`
// (stream id -> Avatar) and `avatar.pose(nowS)` (joint positions, metres). Batches are decoded in
// order of arrival; a stream header is parsed before the packets after it. Streams of a codec
// with no decoder here are kept in `client.others` (stream id -> their header, bytes received).
import { DecodeError } from './errors.js';
import { parseStreamHeader } from './header.js';
import { JitterBuffer } from './jitter.js';
import { forwardKinematics } from './kinematics.js';
import { DATA, HEADER, Reader, splitBatch } from './packets.js';
import { HoldingDecoder, hasDecoder } from './stream.js';

const now = () => performance.now() / 1000;
export const REPAIR_HOLD_S = 0.2; // stream/client.py's: how long a gap is waited for
export const REPAIR_AGAIN_S = 0.05; // a missing packet is asked for again after this, then twice as long
const MAX_REPAIRS = 256; // stream/packets.py's: the packets one request may name

/**
 * One stream of a room as a viewer keeps it: its decoder (which waits for resent packets) and a
 * jitter buffer of its decoded frames.
 */
export class Avatar {
  /**
   * @param {number} stream the stream id
   * @param {StreamInfo} info its header
   */
  constructor(stream, info) {
    this.stream = stream;
    this.info = info;
    this.name = info.name;
    this.codec = info.codec.codec;
    this.skeleton = info.skeleton;
    this.decoder = new HoldingDecoder(info, REPAIR_HOLD_S);
    this.buffer = new JitterBuffer(info.fps, info.skeleton.numChannels);
    this.frames = 0; // frames decoded
    this.bytes = 0;
    this.errors = 0;
    this.decoded = new Map(); // the last decoded frames by stream frame number (a few seconds)
  }

  /**
   * @param {Packet} p a packet of this stream
   * @param {number} arrivalS when its batch arrived (s)
   */
  take(p, arrivalS) {
    this.bytes += p.payload.length;
    for (const { packet, frames, error } of this.decoder.push(p)) {
      if (error) this.errors += 1;
      if (frames && frames.length) this.#decoded(packet, frames, arrivalS);
    }
  }

  #decoded(p, frames, arrivalS) {
    const C = this.skeleton.numChannels;
    for (let k = 0; k < frames.length / C; k++) {
      this.decoded.set(p.firstFrame + k, frames.slice(k * C, (k + 1) * C));
      this.decoded.delete(p.firstFrame + k - 10 * Math.ceil(this.info.fps));
    }
    this.frames += frames.length / C;
    this.buffer.push(frames, p.firstFrame, arrivalS);
  }

  /**
   * @param {number} [nowS]
   * @param {Float64Array | null} [orientations] joints x 4, filled with each joint's global rotation (w, x, y, z)
   * @returns {Float64Array | null} joint positions (joints x 3, metres) to show at `nowS`, null before the first frame
   */
  pose(nowS = now(), orientations = null) {
    const channels = this.buffer.pose(nowS);
    if (!channels) return null;
    const positions = forwardKinematics(this.skeleton, channels, orientations);
    return positions.map((v) => v / this.skeleton.unitsPerMetre);
  }
}

/**
 * Joins a relay room as a viewer over WebSocket: `client.avatars` (stream id -> Avatar),
 * `client.others` (streams of codecs without a decoder here), `client.statuses` (the relay's
 * status messages).
 */
export class RelayClient {
  /**
   * @param {string} url the relay's ws:// or wss:// address
   * @param {{room: string, token: string, budget?: number, camera?: number[], welcomeS?: number, WebSocketClass?: Function}} options
   *   `budget` (bit/s) and `camera` ([x, y, z] m): what the relay cuts the streams to; `welcomeS`:
   *   how long `connect` waits for the relay's welcome (as Python's client.WELCOME_S)
   */
  constructor(url, { room, token, budget = 0, camera = [0, 0, 0], welcomeS = 10, WebSocketClass = globalThis.WebSocket } = {}) {
    this.url = url;
    this.room = room;
    this.token = token;
    this.settings = { budget, camera };
    this.welcomeS = welcomeS;
    this.decodeMs = 0; // time spent decoding packets so far (ms)
    this.WebSocketClass = WebSocketClass;
    this.avatars = new Map();
    this.statuses = []; // the relay's status messages (a stream that starts live, without its history)
    this.others = new Map();
    this.reader = new Reader();
    this.asked = new Map(); // "stream sequence" -> [when last asked for (s), the wait before the next]
    this.queue = Promise.resolve();
    this.errors = 0;
    this.closed = null;
  }

  /** @returns {Promise<void>} once the relay has let the viewer in (rejected if no welcome comes within `welcomeS`) */
  connect() {
    const query = new URLSearchParams({ room: this.room, role: 'subscribe', token: this.token });
    const ws = new this.WebSocketClass(`${this.url.replace(/\/$/, '')}/ws?${query}`);
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    return new Promise((resolve, reject) => {
      const waiting = setTimeout(() => {
        reject(new Error(`the relay at ${this.url} sent no welcome within ${this.welcomeS} s`));
        ws.close();
      }, this.welcomeS * 1000);
      ws.onmessage = (event) => {
        if (typeof event.data === 'string') {
          const message = JSON.parse(event.data);
          if (message.welcome !== undefined) {
            clearTimeout(waiting);
            this.send(this.settings);
            resolve(this);
          } else if (typeof message.status === 'string') {
            this.statuses.push(message.status);
          }
          return;
        }
        const arrival = now();
        const data = new Uint8Array(event.data);
        this.queue = this.queue.then(() => this.#batch(data, arrival)).catch(() => { this.errors += 1; });
      };
      ws.onclose = (event) => {
        clearTimeout(waiting);
        this.closed = { code: event.code, reason: event.reason };
        reject(new Error(`the relay closed the connection (${event.code} ${event.reason})`));
      };
      ws.onerror = () => {
        clearTimeout(waiting);
        reject(new Error(`cannot connect to ${this.url}`));
      };
    });
  }

  /** @param {{budget?: number, camera?: number[]}} settings new settings for the relay */
  send(settings) {
    Object.assign(this.settings, settings);
    this.ws.send(JSON.stringify(this.settings));
  }

  /** Leave the room. */
  close() {
    this.ws?.close();
  }

  // Ask the relay for the packets the avatars' decoders wait for, each again after REPAIR_AGAIN_S,
  // then after twice as long each time (stream/client.Watcher.repairs).
  #repair(nowS) {
    const wanted = new Set();
    const due = [];
    for (const [stream, avatar] of this.avatars) {
      for (const sequence of avatar.decoder.wanted()) {
        const key = `${stream} ${sequence}`;
        wanted.add(key);
        const [at, wait] = this.asked.get(key) ?? [-Infinity, REPAIR_AGAIN_S / 2];
        if (!(nowS - at >= wait) || due.length >= MAX_REPAIRS) continue;
        this.asked.set(key, [nowS, 2 * wait]);
        due.push([stream, sequence]);
      }
    }
    for (const key of this.asked.keys()) if (!wanted.has(key)) this.asked.delete(key);
    if (due.length && this.ws?.readyState === 1) this.ws.send(JSON.stringify({ repair: due }));
  }

  async #batch(data, arrival) {
    for (const raw of splitBatch(data)) {
      let p;
      try {
        p = this.reader.read(raw);
      } catch (e) {
        if (!(e instanceof DecodeError)) throw e;
        this.errors += 1; // a packet before its keyframe, or a damaged one: the others go on
        continue;
      }
      if (p.kind === HEADER) {
        if (!this.avatars.has(p.stream) && !this.others.has(p.stream)) {
          try {
            const info = await parseStreamHeader(p.payload);
            if (hasDecoder(info.codec.codec)) this.avatars.set(p.stream, new Avatar(p.stream, info));
            else this.others.set(p.stream, { stream: p.stream, name: info.name, codec: info.codec.codec, bytes: 0 });
          } catch (e) {
            if (!(e instanceof DecodeError)) throw e;
            this.errors += 1;
          }
        }
      } else if (p.kind === DATA) {
        const other = this.others.get(p.stream);
        if (other) other.bytes += p.payload.length;
        else {
          const started = performance.now();
          this.avatars.get(p.stream)?.take(p, arrival);
          this.decodeMs += performance.now() - started;
        }
      }
    }
    this.#repair(now());
  }
}
