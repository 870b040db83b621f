"""Motion-primitive codecs: primitives (per-joint primitive databases) and rhythmic
(whole-body primitives)."""
