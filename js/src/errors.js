// Errors of hostile or damaged input: one line saying where (the byte offset when known) and what.

/**
 * Hostile or damaged input: one line saying where (the byte offset when known) and what.
 */
export class DecodeError extends Error {
  /**
   * @param {string} message what was expected
   * @param {number | null} [offset] the byte offset where it went wrong, when known
   */
  constructor(message, offset = null) {
    super(offset === null ? message : `byte ${offset}: ${message}`);
    this.name = 'DecodeError';
    this.offset = offset;
  }
}

/**
 * A decoder that lost its place in a stream (a dropped layer, a lost packet) and waits for a
 * keyframe or a restart point (Python's `mocodec.errors.OutOfStepError`).
 */
export class OutOfStepError extends DecodeError {
  constructor(message) {
    super(message);
    this.name = 'OutOfStepError';
  }
}
