// mocodec in JavaScript: decode live motion streams (the relay's packets, kinwave-live) and kinwave
// .moc files, and pose skeletons, in the browser or in Node, with no dependency.
export { DecodeError, OutOfStepError } from './errors.js';
export { BinaryDecoder } from './binarycoder.js';
export { Reader, splitBatch, codecPayload, HEADER, DATA, KEYFRAME, END, RESTART } from './packets.js';
export { parseStreamHeader } from './header.js';
export { Skeleton } from './skeleton.js';
export { KinwaveLiveDecoder, packetFrames } from './kinwave-live.js';
export { forwardKinematics } from './kinematics.js';
export { decodeMoc, openMoc } from './moc.js';
export { unpackSkeleton } from './compact-skeleton.js';
export { HoldingDecoder, LiveDecoder, hasDecoder } from './stream.js';
export { JitterBuffer } from './jitter.js';
export { Avatar, RelayClient } from './relay-client.js';
