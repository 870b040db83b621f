// The limits every decoder here holds hostile input to, mocodec.limits' values: a header's inflated
// text, a frame rate, the values one decode may make, the frames one packet or chunk may hold.
export const MAX_HEADER_TEXT = 8 << 20;
export const MIN_FPS = 1e-3;
export const MAX_FPS = 10000;
export const MAX_DECODED_VALUES = 2 ** 25;
export const MAX_PAYLOAD_FRAMES = 1 << 20;
