// Errors of hostile or damaged input: one line saying where (the byte offset when known) and what.

export class DecodeError extends Error {
  constructor(message, offset = null) {
    super(offset === null ? message : `byte ${offset}: ${message}`);
    this.name = 'DecodeError';
    this.offset = offset;
  }
}

// A decoder that lost its place in a stream (a dropped layer, a lost packet) and waits for a restart.
export class OutOfStepError extends DecodeError {
  constructor(message) {
    super(message);
    this.name = 'OutOfStepError';
  }
}
