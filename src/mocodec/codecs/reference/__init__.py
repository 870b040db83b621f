"""Reference and baseline codecs: raw floats, lossless, and the generic float compressors
(zstd, SZ3, ZFP, fpzip) a user might pick instead."""
